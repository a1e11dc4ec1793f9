//! The CSV files' columns: a header and the rows of one frame for each file
//! (trajectory, reference, integrals, odometry, safety).

use std::io::{self, Write};

use crate::agent::AgentSpec;
use crate::csv::CsvWriter;
use crate::model::wrap_angle;
use crate::reference::{Order, Reference, Trajectory};
use crate::safety::Outcome;
use crate::sample::{AgentSample, SampleCsv};
use crate::sim::{Frame, Simulation};

/// The header of `trajectory.csv`: one row per agent per logged sample
/// ([`AgentSample`], its fields [`sample::COLUMNS`](crate::sample::COLUMNS)),
/// SI units, radians, `e` and `z` in the follower's body frame, agents
/// numbered from 1.
pub const TRAJECTORY_HEADER: &str = "t,agent,x,y,theta,v,omega,ex,ey,zx,zy,u1,u2,tau_r,tau_l";

/// The header of `trajectory.csv` when some agent is on a velocity base:
/// [`TRAJECTORY_HEADER`] and the commanded `(v*, ω*)`, the command after the
/// base's speed limits and whether they cut it (`sat`, 0 or 1): the fields
/// of [`VelocitySample`](crate::sample::VelocitySample). A velocity agent's
/// `u1,u2,tau_r,tau_l` are `NaN`, a torque agent's five new cells too.
pub const TRAJECTORY_HEADER_VELOCITY: &str = "t,agent,x,y,theta,v,omega,ex,ey,zx,zy,u1,u2,tau_r,tau_l,v_cmd,omega_cmd,v_applied,omega_applied,sat";

/// What a [`CsvLog`](super::CsvLog) writes: a header and, for each frame it is shown, its rows.
pub trait FrameRows {
    /// The header line.
    fn header(&self) -> &'static str;

    /// Called when the run starts (e.g. to take the run's reference).
    fn start(&mut self, _sim: &Simulation) {}

    /// Writes the rows of one frame.
    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()>;
}

/// `trajectory.csv`: one [`AgentSample`] per agent per frame; with the
/// velocity-base columns when `velocity` ([`TRAJECTORY_HEADER_VELOCITY`]).
/// The simulator and the fleet collector write it alike.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrajectoryRows {
    /// Whether to write the velocity-base columns.
    pub velocity: bool,
}

impl TrajectoryRows {
    /// The table for `agents`: with the velocity-base columns when some
    /// agent is on a velocity base, else exactly [`TRAJECTORY_HEADER`].
    pub fn for_agents(agents: &[AgentSpec]) -> TrajectoryRows {
        TrajectoryRows {
            velocity: agents.iter().any(|a| a.velocity_robot().is_some()),
        }
    }

    /// Writes one sample's row.
    pub fn row<W: Write>(&self, sample: &AgentSample, csv: &mut CsvWriter<W>) -> io::Result<()> {
        sample.write_csv(csv, self.velocity)
    }
}

impl FrameRows for TrajectoryRows {
    fn header(&self) -> &'static str {
        if self.velocity {
            TRAJECTORY_HEADER_VELOCITY
        } else {
            TRAJECTORY_HEADER
        }
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        for sample in AgentSample::all(frame) {
            self.row(&sample, csv)?;
        }
        Ok(())
    }
}

/// The header of `reference.csv`: the virtual leader `p_d(t)` at the same logged
/// instants as `trajectory.csv`: position, heading `atan2(ẏ_d, ẋ_d)` (0 at
/// standstill), speed `V_d` and turn rate `ω_d`.
pub const REFERENCE_HEADER: &str = "t,x,y,theta,v,omega";

/// `reference.csv`: the run's reference (taken when the run starts) at each frame.
#[derive(Debug, Clone, Default)]
pub struct ReferenceRows {
    reference: Option<Reference>,
}

impl FrameRows for ReferenceRows {
    fn header(&self) -> &'static str {
        REFERENCE_HEADER
    }

    fn start(&mut self, sim: &Simulation) {
        self.reference = Some(sim.reference().clone());
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        let reference = self.reference.as_ref().ok_or_else(|| {
            io::Error::other("reference.csv: shown a frame before the run started")
        })?;
        let jet = reference.eval(frame.t, Order::Two);
        csv.time(frame.t).nums([
            jet.p[0],
            jet.p[1],
            jet.heading(),
            jet.speed(),
            jet.turn_rate(),
        ]);
        csv.end_row()
    }
}

/// The header of `integrals.csv`: per agent, at the same logged instants as
/// `trajectory.csv`, the running integrals since `t = 0` that make a log
/// exact for identification whatever its logging period
/// ([`crate::identify`]): `s = ∫v dt` (m, the true distance travelled),
/// `theta` the true heading not wrapped (`θ(0) + ∫ω dt`, rad), and
/// `int_1, int_2` the integral of the input the plant received: `∫u1 dt`
/// (N s) and `∫u2 dt` (N m s) for a torque robot, `∫v dt` (m) and `∫ω dt`
/// (rad) of the applied command for a velocity base. They are summed with
/// RK4's weights ([`Frame::input_integral`]), so between any two rows of a
/// torque robot `m Δv + η Δs = Δint_1` and `J Δω + ψ Δθ = Δint_2` hold to
/// rounding, however the input varied in between.
pub const INTEGRALS_HEADER: &str = "t,agent,s,theta,int_1,int_2";

/// `integrals.csv`: one row per agent per frame ([`INTEGRALS_HEADER`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct IntegralRows;

impl FrameRows for IntegralRows {
    fn header(&self) -> &'static str {
        INTEGRALS_HEADER
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        for (i, state) in frame.states.iter().enumerate() {
            let s = frame.distance.get(i).copied().unwrap_or(f64::NAN);
            let [i1, i2] = frame
                .input_integral
                .get(i)
                .copied()
                .unwrap_or([f64::NAN; 2]);
            csv.time(frame.t)
                .int(i as u64 + 1)
                .nums([s, state.theta, i1, i2]);
            csv.end_row()?;
        }
        Ok(())
    }
}

/// The header of `odometry.csv`: what each dead-reckoning agent's controller
/// believed — its pose estimate and `ê`, `ẑ` (eqs. 33, 35) — and `fix`, the
/// number of absolute fixes applied since the previous row. Only agents with
/// odometry have rows.
pub const ODOMETRY_HEADER: &str = "t,agent,x_hat,y_hat,theta_hat,ex_hat,ey_hat,zx_hat,zy_hat,fix";

/// `odometry.csv`: one row per dead-reckoning agent per frame.
#[derive(Debug, Clone, Default)]
pub struct OdometryRows {
    fixes: Vec<u64>,
}

impl FrameRows for OdometryRows {
    fn header(&self) -> &'static str {
        ODOMETRY_HEADER
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        self.fixes.resize(frame.odometers.len(), 0);
        for (i, (odometer, o)) in frame.odometers.iter().zip(frame.outputs).enumerate() {
            let Some(odometer) = odometer else { continue };
            let est = odometer.believed(&frame.states[i]);
            let applied = odometer.fixes_applied();
            csv.time(frame.t)
                .int((i + 1) as u64)
                .nums([
                    est.x,
                    est.y,
                    wrap_angle(est.theta),
                    o.e_hat[0],
                    o.e_hat[1],
                    o.z_hat[0],
                    o.z_hat[1],
                ])
                .int(applied - self.fixes[i]);
            self.fixes[i] = applied;
            csv.end_row()?;
        }
        Ok(())
    }
}

/// The header of `safety.csv` (written when a safety filter runs): per
/// filtering agent per logged frame, `outcome` (0 nominal command, 1
/// filtered, 2 braked: the QP was infeasible), `deadlock` (0 or 1: breaking a
/// deadlock), the law's command and the filtered one (`(v, ω)` for a velocity
/// base, `(u1, u2)` for a torque-driven robot), `min_distance`: the true
/// distance from this robot's point `L` ahead to the nearest other robot's
/// point, and `radius`.
pub const SAFETY_HEADER: &str =
    "t,agent,outcome,deadlock,nominal_1,nominal_2,command_1,command_2,min_distance,radius";

/// `safety.csv`: one row per filtering agent per frame.
#[derive(Debug, Clone, Default)]
pub struct SafetyRows {
    l: Vec<f64>,
    radius: f64,
    points: Vec<[f64; 2]>,
}

impl FrameRows for SafetyRows {
    fn header(&self) -> &'static str {
        SAFETY_HEADER
    }

    fn start(&mut self, sim: &Simulation) {
        self.l = sim.agents().iter().map(|a| a.placement().l()).collect();
        self.radius = sim.safety_radius().unwrap_or(f64::NAN);
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        self.points.clear();
        self.points.extend(
            frame
                .states
                .iter()
                .zip(&self.l)
                .map(|(s, &l)| crate::safety::point(s, l)),
        );
        for (i, o) in frame.safety.iter().enumerate() {
            if !o.enabled {
                continue;
            }
            let p = self.points[i];
            let nearest = self
                .points
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
                .fold(f64::INFINITY, f64::min);
            let outcome = match o.outcome {
                Outcome::Nominal => 0,
                Outcome::Filtered => 1,
                Outcome::Braked => 2,
            };
            csv.time(frame.t)
                .int((i + 1) as u64)
                .int(outcome)
                .int(u64::from(o.deadlock))
                .nums(o.nominal)
                .nums(o.filtered)
                .opt(nearest.is_finite().then_some(nearest))
                .num(self.radius);
            csv.end_row()?;
        }
        Ok(())
    }
}
