//! Observers: what watches a run ([`Observer`], [`Every`]) and the [`Frame`] they see.

use super::{AgentOutput, SafetyOutput, Simulation};
use crate::model::State;
use crate::odometry::Odometer;

/// The simulation at one step, as observers see it.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// Time, s.
    pub t: f64,
    /// Step index (`t = step · dt`).
    pub step: u64,
    /// Whether this is the final frame of the run.
    pub last: bool,
    /// The agents' states.
    pub states: &'a [State],
    /// The agents' controller outputs at these states.
    pub outputs: &'a [AgentOutput],
    /// Each agent's odometer, if it dead-reckons (empty without odometry).
    pub odometers: &'a [Option<Odometer>],
    /// Each agent's safety filter output (empty without a safety filter).
    pub safety: &'a [SafetyOutput],
    /// Each agent's true distance travelled `∫v dt` since `t = 0`, m.
    pub distance: &'a [f64],
    /// Each agent's integral since `t = 0` of the input its plant received:
    /// `∫u1 dt, ∫u2 dt` (N s, N m s) for a torque robot, `∫v dt, ∫ω dt` of
    /// the applied command (m, rad) for a velocity base. Summed with RK4's
    /// weights over the stages, as `distance` and the state are: for a torque
    /// robot `m Δv + η Δs = Δ∫u1` and `J Δω + ψ Δθ = Δ∫u2` hold to rounding
    /// between any two frames.
    pub input_integral: &'a [[f64; 2]],
}

/// An error an observer may return (e.g. an I/O error while logging).
pub type ObserverError = Box<dyn std::error::Error + Send + Sync>;

/// Watches a run from its beginning to its end: logging, statistics, progress
/// (argmin's observers, ripgrep's `Sink`). [`Simulation::run`] calls
/// [`start`](Observer::start) once, [`observe`](Observer::observe) for every
/// frame it is shown and [`finish`](Observer::finish) once after the final
/// frame. How often an observer sees frames is chosen where it is attached
/// ([`Every`]), not inside it.
///
/// When the run fails (a non-finite state, an observer's error) `finish` is not
/// called: an observer that holds a resource releases it when dropped, and a
/// file writer leaves its file incomplete for the caller to remove.
pub trait Observer {
    /// Called once before the first frame, with the simulation about to run
    /// (its agents, reference, configuration and number of steps).
    fn start(&mut self, _sim: &Simulation) -> Result<(), ObserverError> {
        Ok(())
    }

    /// Called for each frame shown to the observer, in order; the final frame
    /// has [`Frame::last`] set.
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError>;

    /// Called once after the final frame of a run that succeeded: flush,
    /// write footers, close.
    fn finish(&mut self) -> Result<(), ObserverError> {
        Ok(())
    }
}

/// A closure is an observer of every frame (no start or finish work).
impl<F: FnMut(&Frame<'_>) -> Result<(), ObserverError>> Observer for F {
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        self(frame)
    }
}

/// An observer shown every `every`-th step (`t = 0, every·dt, …`) and the
/// final frame; `every` of 0 or 1 shows every step. This is the schedule of
/// `trajectory.csv` (`log.dt`): a log's rate is set where it is attached
/// (argmin's `ObserverMode::Every`), and `start`/`finish` pass through.
#[derive(Debug, Clone)]
pub struct Every<O> {
    every: u64,
    observer: O,
}

impl<O> Every<O> {
    /// Shows `observer` every `every`-th step and the final frame.
    pub fn new(every: u64, observer: O) -> Every<O> {
        Every {
            every: every.max(1),
            observer,
        }
    }

    /// Whether this schedule shows `frame`.
    #[inline]
    pub fn shows(&self, frame: &Frame<'_>) -> bool {
        frame.step.is_multiple_of(self.every) || frame.last
    }

    /// The observer, e.g. to read what it gathered.
    pub fn get_ref(&self) -> &O {
        &self.observer
    }

    /// The observer, released from its schedule.
    pub fn into_inner(self) -> O {
        self.observer
    }
}

impl<O: Observer> Observer for Every<O> {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        self.observer.start(sim)
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        if self.shows(frame) {
            self.observer.observe(frame)
        } else {
            Ok(())
        }
    }

    fn finish(&mut self) -> Result<(), ObserverError> {
        self.observer.finish()
    }
}

/// Several observers as one, each hook called on each in order.
impl<const N: usize> Observer for [&mut dyn Observer; N] {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        self.iter_mut().try_for_each(|o| o.start(sim))
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        self.iter_mut().try_for_each(|o| o.observe(frame))
    }

    fn finish(&mut self) -> Result<(), ObserverError> {
        self.iter_mut().try_for_each(|o| o.finish())
    }
}

/// An observer that may be absent (`None` sees nothing).
impl<O: Observer> Observer for Option<O> {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        self.as_mut().map_or(Ok(()), |o| o.start(sim))
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        self.as_mut().map_or(Ok(()), |o| o.observe(frame))
    }

    fn finish(&mut self) -> Result<(), ObserverError> {
        self.as_mut().map_or(Ok(()), |o| o.finish())
    }
}

#[cfg(test)]
mod observer_tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::formation::Leader;
    use crate::formation::agent::AgentSpec;
    use crate::law::control::{Gains, Variant};
    use crate::law::lycomp::{LyComp, LyDerivatives, Placement, PlacementSpec};
    use crate::model::{RobotParams, State};
    use crate::reference::{Circle, Reference};
    use crate::sim::plan::{Plan, SimConfig, Timing};

    /// Records which hooks it saw, in order.
    #[derive(Debug, Default)]
    struct Hooks {
        events: Vec<String>,
        fail_at: Option<u64>,
    }

    impl Observer for Hooks {
        fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
            self.events.push(format!("start {}", sim.steps()));
            Ok(())
        }

        fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
            if self.fail_at == Some(frame.step) {
                return Err("stop here".into());
            }
            self.events.push(format!(
                "{}{}",
                frame.step,
                if frame.last { "!" } else { "" }
            ));
            Ok(())
        }

        fn finish(&mut self) -> Result<(), ObserverError> {
            self.events.push("finish".into());
            Ok(())
        }
    }

    /// A short run of one Table I robot behind a circle: `steps` steps of
    /// 1 ms.
    fn circle(steps: u64) -> Simulation {
        let placement = Placement::new(PlacementSpec {
            lx_off: 0.3,
            ly_off: 0.35,
            l: 0.1,
            comp: LyComp::Exact,
            derivatives: LyDerivatives::Neglect,
        })
        .unwrap();
        let agent = AgentSpec::new(
            "a",
            RobotParams::AGENT1,
            Leader::Reference,
            placement,
            Gains::PAPER,
            Variant::Complete,
            State::at_rest(0.0, 0.0, 0.0),
        )
        .unwrap();
        let reference = Reference::Circle(Circle::new([1.0, 0.0], 0.0, 0.2, 0.2).unwrap());
        let config = SimConfig::new(0.001, steps as f64 * 0.001, Timing::Continuous).unwrap();
        Simulation::new(&Plan::new(vec![agent], reference, config).unwrap())
    }

    #[test]
    fn hooks_run_once_around_the_frames_every_shows() {
        let mut sim = circle(10);
        let mut every = Every::new(4, Hooks::default());
        sim.run(&mut every).unwrap();
        let events = every.into_inner().events;
        assert_eq!(
            events,
            ["start 10", "0", "4", "8", "10!", "finish"].map(String::from)
        );
        // 0 and 1 show every frame; a multiple of the run shows no extra last.
        for (k, want) in [(0, 11), (1, 11), (5, 3), (10, 2), (20, 2)] {
            let mut sim = circle(10);
            let mut every = Every::new(k, Hooks::default());
            sim.run(&mut every).unwrap();
            assert_eq!(every.get_ref().events.len() - 2, want, "every {k}");
        }
    }

    #[test]
    fn a_failed_run_is_not_finished() {
        let mut sim = circle(10);
        let mut hooks = Hooks {
            fail_at: Some(3),
            ..Hooks::default()
        };
        let err = sim.run(&mut hooks).unwrap_err();
        assert!(err.to_string().contains("stop here"), "{err}");
        assert_eq!(hooks.events, ["start 10", "0", "1", "2"].map(String::from));
    }

    #[test]
    fn observers_in_an_array_each_see_every_hook_in_order() {
        let mut sim = circle(3);
        let (mut a, mut b) = (Hooks::default(), Some(Hooks::default()));
        let mut none: Option<Hooks> = None;
        sim.run(&mut [&mut a as &mut dyn Observer, &mut b, &mut none])
            .unwrap();
        let want = ["start 3", "0", "1", "2", "3!", "finish"].map(String::from);
        assert_eq!(a.events, want);
        assert_eq!(b.unwrap().events, want);
    }
}
