//! Fixtures the unit tests share.

use echelon::reference::Circle;

/// The circle through `start` at heading `heading`, driven at `speed` (m/s)
/// and `turn_rate` (rad/s): radius `speed / turn_rate`.
pub(crate) fn circle(start: [f64; 2], heading: f64, speed: f64, turn_rate: f64) -> Circle {
    Circle::new(start, heading, speed, turn_rate).expect("a valid circle")
}
