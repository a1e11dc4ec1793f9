"""Formation control as vectorised multi-agent environments.

- :class:`FormationVecEnv`: a Gymnasium ``VectorEnv`` of ``num_envs``
  environments of ``num_agents`` robots each, stepped in Rust on arrays the
  environment owns (the GIL released);
- :class:`FormationEnv`: one environment as a Gymnasium ``Env`` (for
  ``check_env`` and single-environment libraries);
- :class:`FormationParallelEnv`: one environment as a PettingZoo
  ``ParallelEnv``, robots by name (``robot_0`` …);
- :func:`baseline_policy`: the paper's kinematic law from observations
  alone, the baseline a learned policy is compared with;
- :func:`bench`: agent-steps per second of a Python loop under the baseline.

Each environment is a formation behind a virtual leader moving at constant
speed and turn rate; robot ``i`` holds the leader ``L_X`` ahead and ``L_Y``
to its left in its own frame (the paper's eq. 7), its slot on a lattice
``spacing`` metres apart, drawn per episode; ``obstacles`` static discs
(radii drawn in ``obstacle_radius``) lie on the leader's path, across the
formation's width, clear of the robots' starts (a scenario's episodes hold
the scenario's obstacles instead). With ``model="unicycle"`` an
action is a velocity command ``(v, ω)`` (m/s, rad/s), clipped to
``v_max``, ``omega_max`` and applied through the base model (lags
``tau_v``, ``tau_omega``) for ``dt`` seconds; with ``model="torque"`` the
robots are Table I's (``robot="agent1"`` or ``"agent2"``, eq. 3) and an
action is the wheel torques ``(τ_r, τ_l)`` (N m), clipped to
``±torque_limit`` (prefer ``dt ≤ 0.01`` there: the law's ``K_z = 10``).
With ``safety=True`` the action first goes through the robot's
barrier-certificate filter, which keeps every two robots' points ``l``
ahead at least ``radius`` apart and every point at least ``radius`` from
every obstacle's edge.

An observation is ``10 + 3 K + 4 M`` values (``K = neighbours``, ``M =
seen_obstacles``, by default all obstacles up to 4), body frame:
``e_x, e_y`` (the tracking error, eq. 7), ``v, ω``, the leader's velocity
``(R ṗ_d)_x, (R ṗ_d)_y`` and acceleration ``(R p̈_d)_x, (R p̈_d)_y``,
``L_X, L_Y``, then for the ``K`` nearest robots within ``sense`` metres
their point relative to the robot's point ``dx, dy`` and ``1`` (listed),
then for the ``M`` obstacles whose edge is nearest and within ``sense``
their centre relative to the robot's point ``dx, dy``, their radius and
``1`` (listed) — zeros for padding.

A robot's reward per step is ``−w_t ‖e‖² − w_e ‖a‖² − w_c (c_r + c_o)``
(``a = (v, l ω)`` on velocity bases, ``(τ_r, τ_l)`` on torque robots;
``c_r = 1`` when another robot's point is within ``radius`` of its own,
``c_o = 1`` when an obstacle's edge is; ``weights = (w_t, w_e, w_c)``,
default ``(1, 0.01, 10)``); an environment's reward is the mean over its
robots. Episodes are truncated after ``max_steps`` steps and never
terminate otherwise. ``infos["min_distance"]`` is each environment's
smallest distance between two points, ``infos["obstacle_distance"]`` its
smallest distance from a point to an obstacle's edge (``inf`` without
obstacles).
"""

from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

try:
    import gymnasium
    from gymnasium import spaces
    from gymnasium.vector import AutoresetMode, VectorEnv
    from gymnasium.vector.utils import batch_space
except ImportError as e:  # pragma: no cover - depends on the environment
    raise ImportError("echelon.envs needs gymnasium (pip install gymnasium)") from e

from . import _echelon

__all__ = ["FormationEnv", "FormationParallelEnv", "FormationVecEnv", "baseline_policy", "bench"]

_MODELS = ("unicycle", "torque")
#: Index of the first neighbour's values in an observation (``echelon_core::learn::layout``).
_NEIGHBOURS = 10
#: Values per listed neighbour and per listed obstacle.
_PER_NEIGHBOUR, _PER_OBSTACLE = 3, 4


class _Core:
    """The Rust environments, their buffers and their settings."""

    def __init__(
        self,
        num_envs: int,
        num_agents: int,
        *,
        model: str = "unicycle",
        scenario: Any = None,
        overrides: dict[str, Any] | None = None,
        dt: float | None = None,
        spacing: float = 1.0,
        safety: bool = False,
        radius: float | None = None,
        seed: int | None = None,
        dtype: Any = np.float64,
        l: float = 0.1,
        gain: float = 1.0,
        v_max: float = 0.5,
        omega_max: float = 2.0,
        tau_v: float = 0.0,
        tau_omega: float = 0.0,
        neighbours: int = 4,
        sense: float | None = None,
        weights: tuple[float, float, float] = (1.0, 0.01, 10.0),
        max_steps: int = 500,
        speed: tuple[float, float] = (0.05, 0.2),
        turn: float = 0.1,
        robot: str = "agent1",
        torque_limit: float = 10.0,
        obstacles: int = 0,
        obstacle_radius: tuple[float, float] = (0.1, 0.3),
        seen_obstacles: int | None = None,
    ) -> None:
        if model not in _MODELS:
            raise ValueError(f"model must be one of {_MODELS}, got {model!r}")
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.dtype(np.float64), np.dtype(np.float32)):
            raise ValueError(f"dtype must be float64 or float32, got {self.dtype}")
        counts = (("num_envs", num_envs), ("num_agents", num_agents), ("neighbours", neighbours), ("max_steps", max_steps), ("obstacles", obstacles))
        if seen_obstacles is not None:
            counts += (("seen_obstacles", seen_obstacles),)
        for name, v in counts:
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise TypeError(f"{name} must be an integer, got {type(v).__name__}")
            if v < 0:
                raise ValueError(f"{name} must be ≥ 0, got {v}")
        if num_envs < 1 or num_agents < 1:
            raise ValueError(f"num_envs and num_agents must be ≥ 1, got {num_envs}, {num_agents}")
        self.radius = float(0.4 * spacing if radius is None else radius)
        self.seed = int(np.random.SeedSequence().entropy % 2**63) if seed is None else int(seed)
        if self.seed < 0:
            raise ValueError(f"seed must be ≥ 0, got {self.seed}")
        self.num_envs, self.num_agents, self.safety = int(num_envs), int(num_agents), bool(safety)
        inner_scenario, scenario_overrides = None, None
        if scenario is not None:
            from ._scenario import _checked, as_scenario

            sc = as_scenario("scenario", scenario)
            inner_scenario = sc._inner
            scenario_overrides = {**sc.overrides, **_checked(dict(overrides or {}))}
        elif overrides:
            raise ValueError("overrides need a scenario")
        self.inner = _echelon.VecFormation(
            self.num_envs,
            self.num_agents,
            dt=None if dt is None else float(dt),
            spacing=float(spacing),
            l=float(l),
            radius=self.radius,
            safety=self.safety,
            gain=float(gain),
            v_max=float(v_max),
            omega_max=float(omega_max),
            tau_v=float(tau_v),
            tau_omega=float(tau_omega),
            neighbours=int(neighbours),
            sense=float(3.0 * spacing if sense is None else sense),
            weights=tuple(float(w) for w in weights),
            max_steps=int(max_steps),
            speed=(float(speed[0]), float(speed[1])),
            turn=float(turn),
            seed=self.seed,
            float32=self.dtype == np.float32,
            robot=str(robot) if model == "torque" and scenario is None else None,
            torque_limit=float(torque_limit),
            scenario=inner_scenario,
            overrides=scenario_overrides,
            obstacles=int(obstacles),
            obstacle_radius=(float(obstacle_radius[0]), float(obstacle_radius[1])),
            seen_obstacles=None if seen_obstacles is None else int(seen_obstacles),
        )
        self.model = self.inner.model
        if scenario is not None and model != "unicycle" and model != self.model:
            raise ValueError(f"model={model!r}, but the scenario's robots make it {self.model!r}")
        self.bounds = self.inner.action_bound
        self.dt, self.l = self.inner.dt_l
        self.obs_dim = self.inner.obs_dim
        self.listed = self.inner.listed
        e, n = self.num_envs, self.num_agents
        self.obs = np.zeros((e, n, self.obs_dim), self.dtype)
        self.rewards = np.zeros((e, n), self.dtype)
        self.changed = np.zeros((e, n), self.dtype)
        self.inner.observe(self.obs)

    def actions(self, actions: Any) -> np.ndarray:
        """``actions`` as a C-contiguous array of the environments' dtype and
        shape, else ``ValueError``/``TypeError`` (nothing stepped)."""
        try:
            a = np.asarray(actions)
        except Exception as e:  # a ragged or odd object
            raise ValueError(f"actions: {e}") from e
        if a.dtype.kind not in "fiu" or a.dtype == np.bool_:
            raise TypeError(f"actions must be numbers, got dtype {a.dtype}")
        want = (self.num_envs, self.num_agents, 2)
        if a.shape != want:
            raise ValueError(f"actions must have shape {want}, got {a.shape}")
        return np.ascontiguousarray(a, dtype=self.dtype)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.inner.step(actions, self.obs, self.rewards, self.changed)


def _mask(value: Any, n: int) -> np.ndarray:
    m = np.asarray(value)
    if m.dtype != np.bool_ or m.shape != (n,):
        raise ValueError(f"reset_mask must be a bool array of shape ({n},), got {m.dtype} array of shape {m.shape}")
    return m


def _obs_box(core: _Core, shape: tuple[int, ...]) -> spaces.Box:
    """The observation space: unbounded values, each listed entry's flag in
    ``[0, 1]``, each obstacle's radius ``≥ 0``."""
    k, m = core.listed
    low = np.full(core.obs_dim, -np.inf)
    high = np.full(core.obs_dim, np.inf)
    at = _NEIGHBOURS + _PER_NEIGHBOUR * k
    low[_NEIGHBOURS + 2 : at : _PER_NEIGHBOUR] = 0.0
    high[_NEIGHBOURS + 2 : at : _PER_NEIGHBOUR] = 1.0
    low[at + 2 :: _PER_OBSTACLE] = 0.0
    low[at + 3 :: _PER_OBSTACLE] = 0.0
    high[at + 3 :: _PER_OBSTACLE] = 1.0
    low, high = (np.broadcast_to(b, shape + (core.obs_dim,)).astype(core.dtype) for b in (low, high))
    return spaces.Box(low, high, dtype=core.dtype)


def _action_bounds(core: _Core, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    high = np.broadcast_to(np.array(core.bounds, core.dtype), shape).copy()
    return -high, high


class FormationVecEnv(VectorEnv):
    """``num_envs`` formation environments of ``num_agents`` robots (see the
    module's documentation). ``step`` takes actions of shape ``(num_envs,
    num_agents, 2)``; observations are ``(num_envs, num_agents, obs_dim)``,
    rewards ``(num_envs,)`` (the mean over robots; each robot's in
    ``infos["agent_rewards"]``). Autoreset: ``NEXT_STEP`` (Gymnasium's
    default): the step after an episode ends resets that environment and
    returns its first observation with reward 0, its action ignored.

    ``reset(options={"reset_mask": mask})`` resets the environments ``mask``
    selects and leaves the others untouched. ``copy=False`` returns the
    environment's own buffers (no copy; the next step overwrites them)."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int, num_agents: int, *, copy: bool = True, **kwargs: Any) -> None:
        self._core = _Core(num_envs, num_agents, **kwargs)
        self._copy = bool(copy)
        c = self._core
        self.num_envs = c.num_envs
        self.dtype = c.dtype
        self.single_observation_space = _obs_box(c, (c.num_agents,))
        low, high = _action_bounds(c, (c.num_agents, 2))
        self.single_action_space = spaces.Box(low, high, dtype=c.dtype)
        self.observation_space = batch_space(self.single_observation_space, c.num_envs)
        self.action_space = batch_space(self.single_action_space, c.num_envs)
        self._autoreset = np.zeros(c.num_envs, np.bool_)
        self._seeded = False

    @property
    def safety_radius(self) -> float:
        """The distance between two robots' points the filter keeps (and the
        rewards count as a collision), m."""
        return self._core.radius

    @property
    def poses(self) -> np.ndarray:
        """A new ``(num_envs, num_agents, 3)`` array of x, y, θ."""
        return self._core.inner.poses()

    @property
    def offsets(self) -> np.ndarray:
        """A new ``(num_envs, num_agents, 2)`` array of each robot's ``L_X, L_Y``."""
        return self._core.inner.offsets()

    @property
    def leaders(self) -> np.ndarray:
        """A new ``(num_envs, 3)`` array of each leader's heading (rad),
        speed (m/s) and turn rate (rad/s); every leader starts at the origin."""
        return self._core.inner.leaders()

    @property
    def obstacles(self) -> np.ndarray:
        """A new ``(num_envs, M, 3)`` array of each environment's obstacles:
        centre x, y and radius (m)."""
        return self._core.inner.obstacles()

    @property
    def obs_dim(self) -> int:
        """Values per robot observation."""
        return self._core.obs_dim

    def _out(self, a: np.ndarray) -> np.ndarray:
        return a.copy() if self._copy else a

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)} (known: reset_mask)")
        c = self._core
        m = None if mask is None else _mask(mask, c.num_envs)
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
                raise ValueError(f"seed must be an integer ≥ 0, got {seed!r}")
            super().reset(seed=int(seed))
            c.inner.reset(int(seed), None if m is None else [bool(x) for x in m])
            self._seeded = True
        elif not self._seeded:
            c.inner.reset(c.seed, None if m is None else [bool(x) for x in m])
            self._seeded = True
        else:
            c.inner.reset_next([True] * c.num_envs if m is None else [bool(x) for x in m])
        if m is None:
            self._autoreset[:] = False
        else:
            self._autoreset[m] = False
        c.inner.observe(c.obs)
        return self._out(c.obs), {}

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        c = self._core
        a = c.actions(actions)
        rewards, truncated, closest, clearance = c.step(a)
        terminated = np.zeros(c.num_envs, np.bool_)
        if self._autoreset.any():
            done = self._autoreset.copy()
            c.inner.reset_next([bool(x) for x in done])
            fresh = np.empty_like(c.obs)
            c.inner.observe(fresh)
            c.obs[done] = fresh[done]
            rewards[done] = 0.0
            c.rewards[done] = 0.0
            c.changed[done] = 0.0
            truncated[done] = False
            poses = c.inner.poses()[done]
            closest[done] = _closest(poses, c.l)
            clearance[done] = _clearance(poses, c.inner.obstacles()[done], c.l)
        self._autoreset = truncated | terminated
        infos: dict[str, Any] = {
            "agent_rewards": self._out(c.rewards),
            "min_distance": closest,
            "obstacle_distance": clearance,
        }
        if c.safety:
            infos["safety"] = self._out(c.changed)
        return self._out(c.obs), rewards.astype(c.dtype, copy=False), terminated, truncated, infos


def _points(poses: np.ndarray, l: float) -> np.ndarray:
    """Each robot's point ``l`` ahead, ``(..., 2)``."""
    return poses[..., :2] + l * np.stack([np.cos(poses[..., 2]), np.sin(poses[..., 2])], axis=-1)


def _clearance(poses: np.ndarray, obstacles: np.ndarray, l: float) -> np.ndarray:
    """The smallest distance from a point ``l`` ahead to an obstacle's
    edge, per environment (``inf`` without obstacles)."""
    if obstacles.shape[1] == 0:
        return np.full(poses.shape[0], np.inf)
    p = _points(poses, l)
    d = np.linalg.norm(p[:, :, None, :] - obstacles[:, None, :, :2], axis=-1) - obstacles[:, None, :, 2]
    return d.min(axis=(1, 2))


def _closest(poses: np.ndarray, l: float) -> np.ndarray:
    """The smallest distance between two points ``l`` ahead, per environment."""
    p = _points(poses, l)
    d = np.linalg.norm(p[:, :, None, :] - p[:, None, :, :], axis=-1)
    n = p.shape[1]
    d[:, np.arange(n), np.arange(n)] = np.inf
    return d.min(axis=(1, 2)) if n > 1 else np.full(p.shape[0], np.inf)


class FormationEnv(gymnasium.Env):
    """One formation environment as a Gymnasium ``Env``: observation
    ``(num_agents, obs_dim)``, action ``(num_agents, 2)``, reward the mean
    over robots. Same keywords as :class:`FormationVecEnv`."""

    metadata = {"render_modes": []}

    def __init__(self, num_agents: int = 5, **kwargs: Any) -> None:
        self._vec = FormationVecEnv(1, num_agents, **kwargs)
        self.observation_space = self._vec.single_observation_space
        self.action_space = self._vec.single_action_space

    @property
    def poses(self) -> np.ndarray:
        """A new ``(num_agents, 3)`` array of x, y, θ."""
        return self._vec.poses[0]

    @property
    def obstacles(self) -> np.ndarray:
        """A new ``(M, 3)`` array of the obstacles' centre x, y and radius."""
        return self._vec.obstacles[0]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        obs, _ = self._vec.reset(seed=seed, options=options)
        return obs[0].copy(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = np.asarray(action)
        if a.shape != self.action_space.shape:
            raise ValueError(f"action must have shape {self.action_space.shape}, got {a.shape}")
        obs, r, term, trunc, infos = self._vec.step(a[None])
        info = {k: v[0].copy() if isinstance(v, np.ndarray) else v for k, v in infos.items()}
        return obs[0].copy(), float(r[0]), bool(term[0]), bool(trunc[0]), info


def _parallel_base() -> type:
    try:
        from pettingzoo import ParallelEnv
    except ImportError:  # pragma: no cover - depends on the environment
        return object
    return ParallelEnv


class FormationParallelEnv(_parallel_base()):  # type: ignore[misc]
    """One formation environment as a PettingZoo ``ParallelEnv``: robots
    ``robot_0`` … ``robot_{N−1}``, each with its own observation
    (``(obs_dim,)``), action (``(2,)``: ``v, ω``) and reward. After the
    episode is truncated the agents list is empty until ``reset``. Unknown
    keys of ``reset(options=...)`` are ignored; ``reset_mask`` (a bool array
    of shape ``(1,)``) is known and checked. Same keywords as
    :class:`FormationVecEnv`."""

    metadata = {"name": "echelon_formation_v0", "render_modes": [], "is_parallelizable": True}

    def __init__(self, num_agents: int = 5, **kwargs: Any) -> None:
        self._core = _Core(1, num_agents, **kwargs)
        c = self._core
        self.possible_agents = [f"robot_{i}" for i in range(c.num_agents)]
        self.agents: list[str] = []
        low, high = _action_bounds(c, (2,))
        self._obs_spaces = {a: _obs_box(c, ()) for a in self.possible_agents}
        # The global state (for centralised critics, MAPPO): every robot's
        # observation, robot after robot.
        self.state_space = spaces.Box(-np.inf, np.inf, (c.num_agents * c.obs_dim,), c.dtype)
        self._act_spaces = {a: spaces.Box(low, high, dtype=c.dtype) for a in self.possible_agents}
        self.render_mode = None
        self._seeded = False

    @property
    def safety_radius(self) -> float:
        """See :attr:`FormationVecEnv.safety_radius`."""
        return self._core.radius

    @property
    def poses(self) -> np.ndarray:
        """A new ``(num_agents, 3)`` array of x, y, θ."""
        return self._core.inner.poses()[0]

    @property
    def obstacles(self) -> np.ndarray:
        """A new ``(M, 3)`` array of the obstacles' centre x, y and radius."""
        return self._core.inner.obstacles()[0]

    def observation_space(self, agent: str) -> spaces.Box:
        return self._obs_spaces[agent]

    def state(self) -> np.ndarray:
        """Every robot's current observation, robot after robot
        (``state_space``)."""
        return self._core.obs[0].reshape(-1).copy()

    def action_space(self, agent: str) -> spaces.Box:
        return self._act_spaces[agent]

    def _dict(self, values: np.ndarray) -> dict[str, Any]:
        return {a: values[0, i].copy() for i, a in enumerate(self.possible_agents)}

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
        if options and "reset_mask" in options:
            _mask(options["reset_mask"], 1)
        c = self._core
        if seed is not None:
            c.inner.reset(int(seed), None)
            self._seeded = True
        elif not self._seeded:
            c.inner.reset(c.seed, None)
            self._seeded = True
        else:
            c.inner.reset_next([True])
        c.inner.observe(c.obs)
        self.agents = list(self.possible_agents)
        return self._dict(c.obs), {a: {} for a in self.agents}

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        c = self._core
        unknown = set(actions) - set(self.possible_agents)
        if unknown:
            raise ValueError(f"unknown agents {sorted(unknown)}")
        a = np.zeros((1, c.num_agents, 2), c.dtype)
        for i, name in enumerate(self.possible_agents):
            if name in actions:
                v = np.asarray(actions[name])
                if v.shape != (2,):
                    raise ValueError(f"{name}'s action must have shape (2,), got {v.shape}")
                a[0, i] = v
        a = c.actions(a)
        _, truncated, closest, clearance = c.step(a)
        live = list(self.agents)
        obs = {n: c.obs[0, i].copy() for i, n in enumerate(self.possible_agents) if n in live}
        rewards = {n: float(c.rewards[0, i]) for i, n in enumerate(self.possible_agents) if n in live}
        terms = {n: False for n in live}
        truncs = {n: bool(truncated[0]) for n in live}
        infos = {n: {"min_distance": float(closest[0]), "obstacle_distance": float(clearance[0])} for n in live}
        if c.safety:
            for i, n in enumerate(self.possible_agents):
                if n in live:
                    infos[n]["safety"] = float(c.changed[0, i])
        if truncated[0]:
            self.agents = []
        return obs, rewards, terms, truncs, infos


def baseline_policy(env: Any, ke: float | None = None, kz: float = 10.0) -> Callable[[Any], Any]:
    """The paper's law from observations alone. On velocity bases the
    kinematic law (the first step of the backstepping, eqs. 7–10, as a
    velocity command) with gain ``ke`` (default 1): ``ξ* = R ṗ_d − ke e``,
    ``ω* = ξ*₂ / L_X``, ``v* = ξ*₁ + ω* L_Y``. On torque robots the complete
    law (eqs. 9–13, the cross term cancelled; ``ke`` default 1.5, ``kz``
    10: the paper's gains) as wheel torques.
    For a :class:`FormationVecEnv` or :class:`FormationEnv` it maps an
    observation array ``(..., obs_dim)`` to actions ``(..., 2)``; for a
    :class:`FormationParallelEnv` a dict of observations to a dict of
    actions. The actions are not clipped (the environment clips them)."""
    core = env._vec._core if isinstance(env, FormationEnv) else env._core
    ke = float((1.5 if core.model == "torque" else 1.0) if ke is None else ke)
    kz = float(kz)

    def arrays(obs: Any) -> np.ndarray:
        o = np.ascontiguousarray(obs, dtype=core.dtype)
        out = np.empty(o.shape[:-1] + (2,), core.dtype)
        core.inner.baseline(o, ke, out, kz)
        return out

    if isinstance(env, FormationParallelEnv):

        def dicts(obs: dict[str, Any]) -> dict[str, Any]:
            names = list(obs)
            acts = arrays(np.stack([obs[n] for n in names])) if names else np.empty((0, 2))
            return {n: acts[i] for i, n in enumerate(names)}

        return dicts
    return arrays


def bench(num_envs: int, num_agents: int, *, steps: int = 200, dt: float = 0.01, seed: int = 0, **kwargs: Any) -> float:
    """Agent-steps per second of a Python loop stepping a
    :class:`FormationVecEnv` (unicycle model, ``copy=False``) under
    :func:`baseline_policy` for ``steps`` steps (after 10 to warm up), as
    VMAS users time a scenario with its heuristic policy."""
    env = FormationVecEnv(num_envs, num_agents, dt=dt, seed=seed, copy=False, **kwargs)
    policy = baseline_policy(env)
    obs, _ = env.reset(seed=seed)
    for _ in range(10):
        obs = env.step(policy(obs))[0]
    start = time.perf_counter()
    for _ in range(steps):
        obs = env.step(policy(obs))[0]
    return num_envs * num_agents * steps / (time.perf_counter() - start)
