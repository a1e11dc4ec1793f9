//! A robot's tick: the law on the leader motion (fresh or the link-loss
//! policy's), the safety filter and the plant commanded; under a fleet stop
//! or held by a watchdog ([`super::watchdog`]), zero commanded and the
//! state published.

use echelon::follow::{LeaderView, follow};
use echelon::model::State;
use echelon::reference::STANDSTILL;

use crate::link::{Predicted, predict};
use crate::plant::Plant;
use crate::wire::{Header, LinkStatus, RobotState};

use super::{Halt, Robot, RobotTick, WAITING_PERIOD, Watchdog};

impl<P: Plant> Robot<P> {
    /// Diverged at `now` for reason `why`: zero first, then say so and stop
    /// for good (the guard's breach, or a law command that is not finite).
    fn stop_diverged(&mut self, now: f64, why: &str) -> RobotTick {
        self.halt(Halt::Diverged);
        self.diverged = Some(format!(
            "agent {} diverged at t = {now} s: {why}",
            self.config.agent
        ));
        self.next_tick = f64::INFINITY;
        RobotTick {
            publish: None,
            stats: None,
            done: true,
        }
    }

    /// Runs one controller tick at local time `now` (call when [`is_due`]):
    /// delivers what is due, brings the plant to now, runs the law on the
    /// leader motion (fresh or the link-loss policy's) and commands the plant.
    ///
    /// [`is_due`]: Robot::is_due
    pub fn tick(&mut self, now: f64) -> RobotTick {
        if self.config.driven {
            return self.tick_driven(now);
        }
        let local = now;
        let now = self.fleet_time(now);
        self.deliver_due(now);
        self.check_hazards(now);
        if self.latch.stopped() {
            return self.standstill_tick(now, None);
        }
        if self.synced {
            self.plant.advance(now);
            if let Some(w) = self.watchdog_holding(local) {
                return self.standstill_tick(now, Some(w));
            }
        }
        let prediction = match (self.synced, self.sample) {
            (true, Some(s)) => Some(predict(
                &s,
                now,
                self.config.link_timeout,
                &self.config.loss,
            )),
            _ => None,
        };
        let Some(p) = prediction else {
            return self.waiting_tick(now);
        };
        self.note_link(p.status);

        self.plant.advance(now);
        let state = self.plant.state();
        if let Some(breach) = state.and_then(|s| self.config.bounds.check(&s)) {
            return self.stop_diverged(now, &breach.to_string());
        }
        let publish = match state {
            // Every `state_every`-th tick's state leaves (the first too).
            Some(state) => match self.follow_step(local, now, state, &p) {
                Ok(published) => Some(published)
                    .filter(|_| (self.ticks - 1).is_multiple_of(self.config.state_every)),
                Err(why) => return self.stop_diverged(now, &why),
            },
            None => {
                self.halt(Halt::NoOdometry);
                None
            }
        };

        let stats = (now >= self.next_stats).then(|| {
            self.next_stats += 1.0;
            self.stats_at(now, p.status)
        });
        let done = self.config.duration.is_some_and(|d| now >= d);
        if !done {
            self.schedule_next(now);
        }
        RobotTick {
            publish,
            stats,
            done,
        }
    }

    /// Delivers the delayed leader samples due by fleet time `now`, in
    /// order: each accepted by the tracker becomes the sample.
    #[inline]
    fn deliver_due(&mut self, now: f64) {
        while let Some(&(at, h, s)) = self.delayed.front() {
            if at > now {
                break;
            }
            self.delayed.pop_front();
            if self.tracker.check(h, s.t, at).is_ok() {
                self.sample = Some(s);
            }
        }
    }

    /// A tick while waiting for the leader, at fleet time `now`: stand
    /// still, say so now and then.
    #[inline]
    fn waiting_tick(&mut self, now: f64) -> RobotTick {
        if self.synced {
            self.plant.advance(now);
        }
        self.halt(Halt::NoLeader);
        let t = if self.synced { now } else { 0.0 };
        let publish = self.plant.state().map(|state| {
            self.last = RobotState {
                t,
                agent: self.config.agent,
                link: LinkStatus::Waiting,
                state,
                sigma: self.plant.position_sigma(),
                ..RobotState::default()
            };
            self.header_for(self.last)
        });
        self.next_tick = now + WAITING_PERIOD.min(self.config.period * 10.0);
        RobotTick {
            publish,
            stats: None,
            done: false,
        }
    }

    /// Notes the link's status: back to tracking, or a new loss counted.
    #[inline]
    fn note_link(&mut self, status: LinkStatus) {
        if status == LinkStatus::Tracking {
            self.fresh = true;
        } else if self.fresh {
            self.fresh = false;
            self.tracker.counters.link_losses += 1;
        }
    }

    /// The law on leader motion `p` from `state` at fleet time `now` (local
    /// time `local`), through the safety filter and the backup, commanded to
    /// the plant: the state to publish, or why the run diverged when the
    /// command is not finite (for `stop_diverged`).
    #[inline]
    fn follow_step(
        &mut self,
        local: f64,
        now: f64,
        state: State,
        p: &Predicted,
    ) -> Result<(Header, RobotState), String> {
        let dp = p.motion.dp;
        if dp[0].hypot(dp[1]) > STANDSTILL {
            self.heading = dp[1].atan2(dp[0]);
        }
        let out = follow(
            &self.config.spec,
            &state,
            LeaderView::Motion {
                motion: p.motion,
                speed: p.speed,
                turn_rate: p.turn_rate,
                heading: self.heading,
            },
        );
        let nominal = out.command();
        let sigma = self.plant.position_sigma();
        let reverse = self.plan_backup(&state);
        let cmd = match self.safety.as_mut() {
            Some(s) => {
                let error = out.law.e[0].hypot(out.law.e[1]);
                let seen = super::safety::Seen {
                    me: &state,
                    sigma,
                    error,
                    reverse,
                };
                s.act(&self.config, local, now, seen, nominal)
            }
            None => self.config.spec.act(now, &state, nominal, None).command,
        };
        let cmd = self.within_backup(&state, cmd);
        if !cmd.values().iter().all(|v| v.is_finite()) {
            // A leader sample that is finite but far beyond any
            // robot (a position of 1e308 m off the wire) overflows
            // the law: the NaN never reaches the plant; the run has
            // diverged, and says so.
            return Err(format!(
                "the law's command {:?} is not finite (leader at {:?}, velocity {:?})",
                cmd.values(),
                p.motion.p,
                p.motion.dp
            ));
        }
        let act = self.plant.command(cmd);
        let (dv, domega) = self.plant.accelerations();
        self.last = RobotState {
            t: now,
            agent: self.config.agent,
            link: p.status,
            state,
            dv,
            domega,
            e: out.law.e,
            z: out.law.z,
            u: act.u,
            tau: act.tau,
            leader: out.leader,
            velocity: act.velocity_sample(cmd),
            sigma,
            odometry: None,
        };
        self.ticks += 1;
        Ok(self.header_for(self.last))
    }

    /// The next tick one control period on; late by more than a period
    /// (the plant keeps moving in real time), one period from `now`.
    #[inline]
    fn schedule_next(&mut self, now: f64) {
        let period = self.config.period;
        self.next_tick += period;
        if now - self.next_tick > period {
            // Late by more than a period: the plant keeps moving in real
            // time; the controller resumes on the next tick from now.
            self.overruns += 1;
            self.next_tick = now + period;
        }
    }

    /// A tick under a fleet stop, or held by watchdog `held`, at fleet
    /// time `now`: zero commanded, the state published (`stopped` or
    /// `held`; `waiting` while its clock is not the leader's), the counters
    /// once per fleet second, ticks every control period as when
    /// following.
    fn standstill_tick(&mut self, now: f64, held: Option<Watchdog>) -> RobotTick {
        if self.synced {
            self.plant.advance(now);
        }
        self.halt(match (held, self.hazards.is_empty()) {
            (Some(w), _) => Halt::Held(w),
            (None, true) => Halt::Stopped,
            (None, false) => Halt::Hazard,
        });
        let (t, link) = match (self.synced, held) {
            (false, _) => (0.0, LinkStatus::Waiting),
            (true, Some(_)) => (now, LinkStatus::Held),
            (true, None) => (now, LinkStatus::Stopped),
        };
        // Held while its plant has no state now (a ROS 2 base's odometry
        // gone): its last known state, so that the fleet sees it held where
        // it was last seen — its followers stop following it, its
        // neighbours take it at rest there — not a stream gone silent.
        let known = (held.is_some() && self.seq > 0).then_some(self.last.state);
        let current = self.plant.state();
        let publish = current.or(known).map(|state| {
            let (dv, domega) = match current {
                Some(_) => self.plant.accelerations(),
                None => (0.0, 0.0),
            };
            self.last = RobotState {
                t,
                agent: self.config.agent,
                link,
                state,
                dv,
                domega,
                e: self.last.e,
                leader: self.last.leader,
                velocity: self
                    .config
                    .spec
                    .velocity_robot()
                    .map(|_| echelon::sample::VelocitySample::default()),
                sigma: self.plant.position_sigma(),
                ..RobotState::default()
            };
            self.header_for(self.last)
        });
        let stats = (self.synced && now >= self.next_stats).then(|| {
            self.next_stats += 1.0;
            self.stats_at(now, link)
        });
        let done = self.config.duration.is_some_and(|d| now >= d);
        let period = self.config.period;
        self.next_tick = if !self.synced {
            now + WAITING_PERIOD.min(period * 10.0)
        } else if now - self.next_tick > period {
            now + period
        } else {
            self.next_tick + period
        };
        RobotTick {
            publish,
            stats,
            done,
        }
    }
}

/// Where in each fleet second robot `agent` publishes its counters (s, in
/// `[0, 1)`): spread over the second by the golden ratio, so that the
/// robots that set their clocks on the same reference sample (a host's, a
/// fleet's) do not all publish in the same tick. At one instant, a host's
/// hundreds of stats fill its Zenoh queue, and each put then waits up to
/// `wait_before_drop` (1 ms) before its sample is dropped: 125 robots held
/// their host 125 ms once a second (the reference → robot p99 of a
/// thousand-robot fleet, BENCHMARKS.md).
pub(crate) fn stats_phase(agent: u32) -> f64 {
    (f64::from(agent) * 0.618_033_988_749_895).fract()
}
