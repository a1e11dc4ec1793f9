//! The fleet clock: monotonic, scaled, shared by every process.
//!
//! Fleet time `t = offset + K · (monotonic now − start)`, with `K` the time
//! scale (`--time-scale`, 1 for real time). Every duration in the fleet (rates,
//! timeouts, `--duration`, `--outage`, `--delay`) is in fleet seconds, so a run
//! at `K = 10` is the same run ten times faster. A robot syncs its clock to the
//! first message of its leader stream ([`FleetClock::sync`]): fleet time is the
//! reference's time.

use std::time::{Duration, Instant};

/// A monotonic clock running `scale` times faster than real time.
#[derive(Debug, Clone, Copy)]
pub struct FleetClock {
    start: Instant,
    scale: f64,
    offset: f64,
}

impl FleetClock {
    /// A clock reading 0 now, running at `scale` × real time (`scale > 0`).
    pub fn new(scale: f64) -> FleetClock {
        FleetClock {
            start: Instant::now(),
            scale,
            offset: 0.0,
        }
    }

    /// The time scale `K`.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Fleet time at `instant`, s.
    pub fn at(&self, instant: Instant) -> f64 {
        let elapsed = instant.saturating_duration_since(self.start).as_secs_f64();
        self.offset + self.scale * elapsed
    }

    /// Fleet time now, s.
    pub fn now(&self) -> f64 {
        self.at(Instant::now())
    }

    /// Makes the clock read `t` at `instant` from now on.
    pub fn sync(&mut self, t: f64, instant: Instant) {
        let elapsed = instant.saturating_duration_since(self.start).as_secs_f64();
        self.offset = t - self.scale * elapsed;
    }

    /// Real time that `dt` fleet seconds take.
    pub fn real(&self, dt: f64) -> Duration {
        Duration::from_secs_f64((dt / self.scale).clamp(0.0, 1e9))
    }

    /// Sleeps until fleet time `t` (returns at once if it has passed), waking
    /// at least every `max_nap` real time so that a stop request is seen.
    pub fn sleep_until(&self, t: f64, max_nap: Duration) {
        let left = t - self.now();
        if left > 0.0 {
            std::thread::sleep(self.real(left).min(max_nap));
        }
    }
}

/// The fleet's time as a process that follows no one learns it: from the
/// leader's reference samples it hears, each one's time less its arrival on
/// the process's own clock. For the processes that act at fleet times
/// (`--die-at`, `--fault-at`, `fleet garbage --from`) without a leader
/// stream of their own: the operator's heartbeat, a simulated base, `fleet
/// garbage`, a router.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ReferenceTime {
    /// Fleet time − local time, from the newest reference heard.
    offset: Option<f64>,
}

impl ReferenceTime {
    /// The time of the reference sample `payload`, if it is one.
    pub fn of(payload: &[u8]) -> Option<f64> {
        match crate::wire::decode(payload) {
            Ok(crate::wire::Message::Reference(_, r)) => Some(r.t),
            _ => None,
        }
    }

    /// Takes `payload`, arrived at local time `at`: a reference sample
    /// sets the offset. Whether it was one.
    pub fn hear(&mut self, payload: &[u8], at: f64) -> bool {
        let Some(t) = Self::of(payload) else {
            return false;
        };
        self.offset = Some(t - at);
        true
    }

    /// Fleet time − local time (`None`: no reference heard yet).
    pub fn offset(&self) -> Option<f64> {
        self.offset
    }

    /// Fleet time at local time `local` (`None`: no reference heard yet).
    pub fn at(&self, local: f64) -> Option<f64> {
        self.offset.map(|o| local + o)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sync_sets_the_reading_and_scale_applies() {
        let mut c = FleetClock::new(10.0);
        let now = Instant::now();
        c.sync(5.0, now);
        assert!((c.at(now) - 5.0).abs() < 1e-12);
        let later = now + Duration::from_millis(100);
        assert!((c.at(later) - 6.0).abs() < 1e-9, "{}", c.at(later));
        assert_eq!(c.real(1.0), Duration::from_millis(100));
    }
}
