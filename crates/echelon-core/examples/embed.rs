//! The kernel in a control loop of your own, no file, scenario or simulator:
//! three TurtleBot 4s (the preset's lags and limits) take a wedge behind a
//! circle (the two behind start on each other's side and must cross),
//! each commanding its base through the kinematic law (eqs. 7–10)
//! and the barrier-certificate safety filter, 50 Hz, RK4 between commands.
//! `cargo run -p echelon-core --example embed`; `cargo test` runs it too.

use echelon_core::law::control::{LeaderMotion, Offset};
use echelon_core::law::kinematic::kinematic_law;
use echelon_core::model::State;
use echelon_core::model::base::VelocityBase;
use echelon_core::reference::{Circle, Order, Trajectory};
use echelon_core::safety::{Neighbour, Outcome, SafetyConfig, SafetyFilter};

/// What `seconds` of the loop did: each robot's final `‖e‖` (m), the closest
/// two robots' points came (m), the filter's radius (m), and how many
/// commands the filter changed.
struct Run {
    errors: [f64; 3],
    closest: f64,
    radius: f64,
    changed: usize,
}

fn run(seconds: f64) -> Result<Run, Box<dyn std::error::Error>> {
    let (dt, l, ke, base) = (0.02, 0.1, 1.0, VelocityBase::TURTLEBOT4);
    let reference = Circle::new([0.0, 0.0], 0.0, 0.2, 0.1)?; // 2 m radius, 0.2 m/s
    // Where each robot holds the reference, in its own frame: `L_X = L_Xoff + L`
    // ahead, `L_Y = L_Yoff` to the left (no curvature compensation here:
    // `law::lycomp::Placement` gives `L_Ycomp` and its derivatives).
    let slot = |x: f64, y: f64| Offset {
        lx: x + l,
        ly: y,
        dly: 0.0,
        ddly: 0.0,
    };
    let slots = [slot(0.0, 0.0), slot(0.8, -0.6), slot(0.8, 0.6)]; // on it; behind, left; behind, right
    let mut robots = [(0.3, 0.0), (-0.8, -0.6), (-0.8, 0.6)].map(|(x, y)| State {
        x,
        y,
        ..State::default()
    });
    let config = SafetyConfig::new(0.4, 2.0, 2.0)?;
    let mut filters = [(); 3].map(|_| SafetyFilter::new(config).with_period(dt));
    let point = |s: &State| [s.x + l * s.theta.cos(), s.y + l * s.theta.sin()];
    let (mut errors, mut closest, mut changed) = ([0.0; 3], f64::INFINITY, 0);
    let mut neighbours = Vec::with_capacity(2); // reused: the loop does not allocate
    for step in 0..(seconds / dt).round() as usize {
        let t = step as f64 * dt;
        let leader = LeaderMotion::of_jet(&reference.eval(t, Order::Two));
        let seen = robots; // every robot acts on the same instant's states
        for (i, robot) in robots.iter_mut().enumerate() {
            let law = kinematic_law(robot, &leader, &slots[i], ke);
            neighbours.clear();
            for other in seen
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, s)| s)
            {
                neighbours.push(Neighbour::of_state(other, l, None, true));
                let (p, q) = (point(robot), point(other));
                closest = closest.min((p[0] - q[0]).hypot(p[1] - q[1]));
            }
            let safe = filters[i].velocity(t, robot, l, law.cmd, &base, &neighbours, &[]);
            changed += usize::from(safe.outcome != Outcome::Nominal);
            *robot = base.rk4_step(robot, safe.command, dt);
            errors[i] = law.e[0].hypot(law.e[1]);
        }
    }
    Ok(Run {
        errors,
        closest,
        radius: config.radius,
        changed,
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let r = run(60.0)?;
    println!(
        "final ‖e‖ per robot (m): {:.4?}; closest points {:.3} m (radius {} m); {} commands filtered",
        r.errors, r.closest, r.radius, r.changed
    );
    Ok(())
}

#[test]
fn the_wedge_forms_and_the_robots_keep_apart() {
    let r = run(60.0).unwrap();
    assert!(r.errors.iter().all(|&e| e < 0.01), "{:?}", r.errors);
    assert!(r.closest >= r.radius - 1e-3, "{} < {}", r.closest, r.radius);
    assert!(r.changed > 0, "the crossing never needed the filter");
}
