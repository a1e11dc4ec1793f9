//! `echelon.envs`' engine: the kernel's vectorised formation environments
//! ([`echelon::learn::VecFormation`]) stepped on caller-owned numpy arrays
//! (float64, or float32 when made so), the GIL released. The Python classes
//! (`python/echelon/envs.py`) check shapes and convert dtypes; this layer
//! checks again what it reads (shape, dtype, layout, finite actions) and
//! changes nothing when one is wrong.

use echelon::base::{VelocityBase, VelocityBaseSpec};
use echelon::control::Gains;
use echelon::learn::{
    EnvConfig, EnvFacts, FixedEpisode, PlanRobots, Scalar, VecFormation, Weights, baseline,
    baseline_torque,
};
use echelon::model::RobotParams;
use echelon::reference::Reference;
use numpy::{
    Element, PyArray1, PyArray3, PyArrayMethods, PyReadonlyArrayDyn, PyReadwriteArrayDyn,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors;
use crate::scenario::{OverrideArgs, PyScenario};

/// Obstacles an observation lists unless told: all of them up to this many.
const DEFAULT_SEEN_OBSTACLES: usize = 4;

/// The environments and their dtype.
#[pyclass(module = "echelon._echelon", name = "VecFormation")]
pub(crate) struct PyVecFormation {
    inner: VecFormation,
    float32: bool,
    facts: Vec<EnvFacts>,
}

/// `name` refused: not a (`writeable`) array of `T` of exactly `shape`,
/// C-contiguous (`got`: the shape it has, when it is an array of `T`).
fn refused<T>(name: &str, writeable: &str, shape: &[usize], got: Option<&[usize]>) -> PyErr {
    let got = got.map_or_else(String::new, |g| format!(", got shape {g:?}"));
    errors::value(format!(
        "{name} must be a C-contiguous {writeable}{} array of shape {shape:?}{got}",
        dtype::<T>()
    ))
}

/// A caller's array of `T` of exactly `shape`, C-contiguous, read.
fn input<'py, T: Element>(
    name: &str,
    obj: &Bound<'py, PyAny>,
    shape: &[usize],
) -> PyResult<PyReadonlyArrayDyn<'py, T>> {
    let a = obj
        .extract::<PyReadonlyArrayDyn<'py, T>>()
        .map_err(|_| refused::<T>(name, "", shape, None))?;
    if a.shape() == shape && a.is_c_contiguous() {
        Ok(a)
    } else {
        Err(refused::<T>(name, "", shape, Some(a.shape())))
    }
}

/// A caller's array of `T` of exactly `shape`, C-contiguous, written.
fn output<'py, T: Element>(
    name: &str,
    obj: &Bound<'py, PyAny>,
    shape: &[usize],
) -> PyResult<PyReadwriteArrayDyn<'py, T>> {
    let a = obj
        .extract::<PyReadwriteArrayDyn<'py, T>>()
        .map_err(|_| refused::<T>(name, "writeable ", shape, None))?;
    if a.shape() == shape && a.is_c_contiguous() {
        Ok(a)
    } else {
        Err(refused::<T>(name, "writeable ", shape, Some(a.shape())))
    }
}

fn dtype<T>() -> &'static str {
    if std::mem::size_of::<T>() == 4 {
        "float32"
    } else {
        "float64"
    }
}

impl PyVecFormation {
    fn shape(&self) -> (usize, usize, usize) {
        let c = self.inner.config();
        (c.num_envs, c.num_agents, self.inner.obs_dim())
    }

    fn observe_as<T: Element + Scalar>(
        &self,
        py: Python<'_>,
        out: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let (e, n, d) = self.shape();
        let mut out = output::<T>("obs", out, &[e, n, d])?;
        let buf = out.as_slice_mut().map_err(errors::value)?;
        let inner = &self.inner;
        py.detach(|| inner.observe(buf));
        Ok(())
    }

    fn step_as<T: Element + Scalar>(
        &mut self,
        py: Python<'_>,
        actions: &Bound<'_, PyAny>,
        obs: &Bound<'_, PyAny>,
        rewards: &Bound<'_, PyAny>,
        changed: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let (e, n, d) = self.shape();
        let actions = input::<T>("actions", actions, &[e, n, 2])?;
        let mut obs = output::<T>("obs", obs, &[e, n, d])?;
        let mut rewards = output::<T>("rewards", rewards, &[e, n])?;
        let mut changed = output::<T>("changed", changed, &[e, n])?;
        let a = actions.as_slice().map_err(errors::value)?;
        if let Some(k) = echelon::learn::first_not_finite(a) {
            return Err(errors::value(format!(
                "actions[{}, {}, {}] = {} is not finite: nothing was stepped",
                k / (2 * n),
                (k / 2) % n,
                k % 2,
                a[k].get()
            )));
        }
        let (o, r, c) = (
            obs.as_slice_mut().map_err(errors::value)?,
            rewards.as_slice_mut().map_err(errors::value)?,
            changed.as_slice_mut().map_err(errors::value)?,
        );
        let (inner, facts) = (&mut self.inner, &mut self.facts);
        py.detach(|| inner.step(a, o, r, c, facts));
        Ok(())
    }
}

#[pymethods]
impl PyVecFormation {
    #[new]
    #[pyo3(signature = (num_envs, num_agents, *, dt, spacing, l, radius, safety, gain, v_max,
        omega_max, tau_v, tau_omega, neighbours, sense, weights, max_steps, speed, turn, seed, float32,
        robot=None, torque_limit=10.0, scenario=None, overrides=None, obstacles=0,
        obstacle_radius=(0.1, 0.3), seen_obstacles=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        num_envs: usize,
        num_agents: usize,
        dt: Option<f64>,
        spacing: f64,
        l: f64,
        radius: f64,
        safety: bool,
        gain: f64,
        v_max: f64,
        omega_max: f64,
        tau_v: f64,
        tau_omega: f64,
        neighbours: usize,
        sense: f64,
        weights: (f64, f64, f64),
        max_steps: u64,
        speed: (f64, f64),
        turn: f64,
        seed: u64,
        float32: bool,
        robot: Option<&str>,
        torque_limit: f64,
        scenario: Option<PyRef<'_, PyScenario>>,
        overrides: Option<OverrideArgs>,
        obstacles: usize,
        obstacle_radius: (f64, f64),
        seen_obstacles: Option<usize>,
    ) -> PyResult<Self> {
        let robot = robot
            .map(|name| {
                RobotParams::preset(name)
                    .ok_or_else(|| {
                        errors::value(format!(
                            "robot must be \"agent1\" or \"agent2\" (Table I), got {name:?}"
                        ))
                    })?
                    .with_torque_limit(Some(torque_limit))
                    .map_err(|e| errors::param(&e))
            })
            .transpose()?;
        let base = VelocityBase::new(VelocityBaseSpec {
            v_max,
            omega_max,
            tau_v,
            tau_omega,
            ..VelocityBase::IDEAL.spec()
        })
        .map_err(|e| errors::param(&e))?;
        let mut config = EnvConfig {
            num_envs,
            num_agents,
            dt: dt.unwrap_or(0.05),
            spacing,
            l,
            radius,
            safety,
            gain,
            base,
            robot,
            neighbours,
            sense,
            obstacles,
            obstacle_radius,
            seen_obstacles: seen_obstacles.unwrap_or(obstacles.min(DEFAULT_SEEN_OBSTACLES)),
            weights: Weights {
                tracking: weights.0,
                effort: weights.1,
                collision: weights.2,
            },
            max_steps,
            speed,
            turn,
        };
        let inner = match scenario {
            None => VecFormation::new(config, seed),
            Some(sc) => {
                let run = sc.build(sc.py(), overrides.as_ref())?;
                let (fixed, robots, l) =
                    FixedEpisode::of_plan(&run.plan).map_err(|e| errors::param(&e))?;
                config.seen_obstacles =
                    seen_obstacles.unwrap_or(fixed.obstacles.len().min(DEFAULT_SEEN_OBSTACLES));
                config.dt = dt.unwrap_or(run.plan.config().dt);
                config.l = l;
                match robots {
                    PlanRobots::Velocity(b) => config.base = b,
                    PlanRobots::Torque(r) => {
                        config.robot = Some(
                            r.with_torque_limit(Some(r.torque_limit().unwrap_or(torque_limit)))
                                .map_err(|e| errors::param(&e))?,
                        );
                    }
                }
                VecFormation::fixed(config, fixed, seed)
            }
        }
        .map_err(|e| errors::param(&e))?;
        Ok(PyVecFormation {
            inner,
            float32,
            facts: vec![EnvFacts::default(); num_envs],
        })
    }

    /// Values per robot observation.
    #[getter]
    fn obs_dim(&self) -> usize {
        self.inner.obs_dim()
    }

    /// The bound on each action component: `(v_max, ω_max)` or the torque
    /// limit on both wheels.
    #[getter]
    fn action_bound(&self) -> (f64, f64) {
        let [a, b] = self.inner.config().action_bound();
        (a, b)
    }

    /// `"unicycle"` (velocity bases) or `"torque"`.
    #[getter]
    fn model(&self) -> &'static str {
        if self.inner.config().robot.is_some() {
            "torque"
        } else {
            "unicycle"
        }
    }

    /// The step, s, and the point ahead kept apart, m.
    #[getter]
    fn dt_l(&self) -> (f64, f64) {
        (self.inner.config().dt, self.inner.config().l)
    }

    /// Reseeds every environment from `seed` and resets those `mask` selects
    /// (all when `None`).
    #[pyo3(signature = (seed, mask=None))]
    fn reset(&mut self, seed: u64, mask: Option<Vec<bool>>) -> PyResult<()> {
        let e = self.shape().0;
        if let Some(m) = mask.as_ref().filter(|m| m.len() != e) {
            return Err(errors::value(format!(
                "reset_mask must have {e} entries, got {}",
                m.len()
            )));
        }
        self.inner.reset(seed, mask.as_deref());
        Ok(())
    }

    /// Resets the environments `mask` selects with their next episodes.
    fn reset_next(&mut self, mask: Vec<bool>) -> PyResult<()> {
        let e = self.shape().0;
        if mask.len() != e {
            return Err(errors::value(format!(
                "mask must have {e} entries, got {}",
                mask.len()
            )));
        }
        self.inner.reset_next(&mask);
        Ok(())
    }

    /// Writes the observations into `out` (`(E, N, obs_dim)`).
    fn observe(&self, py: Python<'_>, out: &Bound<'_, PyAny>) -> PyResult<()> {
        if self.float32 {
            self.observe_as::<f32>(py, out)
        } else {
            self.observe_as::<f64>(py, out)
        }
    }

    /// One step under `actions` (`(E, N, 2)`): observations, per-robot
    /// rewards and filter changes into the arrays given; returns the
    /// environments' mean rewards, truncations, closest distances between
    /// points and from a point to an obstacle's edge.
    #[allow(clippy::type_complexity)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        actions: &Bound<'py, PyAny>,
        obs: &Bound<'py, PyAny>,
        rewards: &Bound<'py, PyAny>,
        changed: &Bound<'py, PyAny>,
    ) -> PyResult<(
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<f64>>,
    )> {
        if self.float32 {
            self.step_as::<f32>(py, actions, obs, rewards, changed)?;
        } else {
            self.step_as::<f64>(py, actions, obs, rewards, changed)?;
        }
        let f = &self.facts;
        Ok((
            PyArray1::from_iter(py, f.iter().map(|x| x.reward)),
            PyArray1::from_iter(py, f.iter().map(|x| x.truncated)),
            PyArray1::from_iter(py, f.iter().map(|x| x.min_distance)),
            PyArray1::from_iter(py, f.iter().map(|x| x.obstacle_distance)),
        ))
    }

    /// A new `(E, M, 3)` float64 array of each environment's obstacles: x,
    /// y of the centre and the radius, m.
    fn obstacles<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let e = self.shape().0;
        let m = self.inner.config().obstacles;
        let flat: Vec<f64> = (0..e)
            .flat_map(|k| {
                self.inner
                    .obstacles(k)
                    .iter()
                    .flat_map(|o| [o.x(), o.y(), o.r()])
            })
            .collect();
        PyArray1::from_vec(py, flat).reshape([e, m, 3])
    }

    /// `(neighbours, seen_obstacles)`: entries per observation.
    #[getter]
    fn listed(&self) -> (usize, usize) {
        let c = self.inner.config();
        (c.neighbours, c.seen_obstacles)
    }

    /// A new `(E, N, 3)` float64 array of the robots' x, y, θ.
    fn poses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let (e, n, _) = self.shape();
        let flat: Vec<f64> = self
            .inner
            .states()
            .flat_map(|s| [s.x, s.y, s.theta])
            .collect();
        PyArray1::from_vec(py, flat).reshape([e, n, 3])
    }

    /// The robots' slots: `(E, N, 2)` of `L_X`, `L_Y`.
    fn offsets<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let (e, n, _) = self.shape();
        let flat: Vec<f64> = (0..e).flat_map(|k| self.inner.slots(k)).flatten().collect();
        PyArray1::from_vec(py, flat).reshape([e, n, 2])
    }

    /// Each environment's leader: `(E, 3)` of its heading (rad), speed
    /// (m/s) and turn rate (rad/s); it starts at the origin (NaN for a
    /// scenario's reference that is not a circle or line).
    fn leaders<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
        let e = self.shape().0;
        let flat: Vec<f64> = (0..e)
            .flat_map(|k| match self.inner.leader(k) {
                Reference::Circle(c) => [c.heading(), c.speed(), c.turn_rate()],
                _ => [f64::NAN; 3],
            })
            .collect();
        PyArray1::from_vec(py, flat).reshape([e, 3])
    }

    /// The baseline from observations (`(..., obs_dim)`) into actions
    /// (`(..., 2)`), both of the environments' dtype: the kinematic law
    /// (gain `ke`) on velocity bases, the complete law (`ke`, `kz`) as wheel
    /// torques on torque-driven robots.
    #[pyo3(signature = (obs, ke, out, kz=10.0))]
    fn baseline(
        &self,
        py: Python<'_>,
        obs: &Bound<'_, PyAny>,
        ke: f64,
        out: &Bound<'_, PyAny>,
        kz: f64,
    ) -> PyResult<()> {
        let law = match self.inner.config().robot {
            None => Law::Kinematic(ke),
            Some(robot) => Law::Complete(robot, Gains::new(ke, kz).map_err(|e| errors::param(&e))?),
        };
        if self.float32 {
            baseline_as::<f32>(py, obs, law, out, self.inner.obs_dim())
        } else {
            baseline_as::<f64>(py, obs, law, out, self.inner.obs_dim())
        }
    }
}

/// The baseline: the kinematic law (gain `K_e`) or the complete law.
#[derive(Debug, Clone, Copy)]
enum Law {
    Kinematic(f64),
    Complete(RobotParams, Gains),
}

fn baseline_as<T: Element + Scalar>(
    py: Python<'_>,
    obs: &Bound<'_, PyAny>,
    law: Law,
    out: &Bound<'_, PyAny>,
    d: usize,
) -> PyResult<()> {
    let o = obs
        .extract::<PyReadonlyArrayDyn<'_, T>>()
        .map_err(|_| errors::value(format!("obs must be a {} array", dtype::<T>())))?;
    let mut a = out
        .extract::<PyReadwriteArrayDyn<'_, T>>()
        .map_err(|_| errors::value(format!("out must be a writeable {} array", dtype::<T>())))?;
    let (os, as_) = (o.shape().to_vec(), a.shape().to_vec());
    if os.last() != Some(&d) || as_.last() != Some(&2) || os[..os.len() - 1] != as_[..as_.len() - 1]
    {
        return Err(errors::value(format!(
            "obs (…, {d}) and out (…, 2) must agree, got {os:?} and {as_:?}"
        )));
    }
    let src = o.as_slice().map_err(errors::value)?;
    let dst = a.as_slice_mut().map_err(errors::value)?;
    py.detach(|| match law {
        Law::Kinematic(ke) => baseline(src, d, ke, dst),
        Law::Complete(robot, gains) => baseline_torque(src, d, &robot, gains, dst),
    });
    Ok(())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyVecFormation>()
}
