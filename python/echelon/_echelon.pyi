"""Type stubs of the extension module `echelon._echelon` (python/src). The
public API is the `echelon` package, which wraps these."""

from os import PathLike
from typing import Any, Callable, Literal, TypedDict

import numpy as np
import numpy.typing as npt

__version__: str
SWEEP_HEADER: str

Law = Literal["paper", "complete"]

class Overrides(TypedDict, total=False):
    """`echelon run`'s flags; absent or None: the scenario's own."""

    dt: float | None
    duration: float | None
    log_dt: float | None
    law: Law | None
    seed: int | None

class Grid(TypedDict, total=False):
    """A sweep grid (`echelon sweep`'s lists) and the dt, duration overrides."""

    zeta: list[float]
    zeta_model: str
    ed: list[float]
    eb: list[float]
    slip: list[float]
    fix_every: list[int]
    seeds: list[int]
    gamma: float
    transient: float | None
    dt: float | None
    duration: float | None

class ScenarioError(ValueError):
    """A scenario that cannot be loaded or built: `file:line:column: field: message`."""

    file: str
    line: int
    column: int
    field: str
    message: str
    path: tuple[str | int, ...] | None

class SimulationError(RuntimeError):
    """A run that diverged or could not write its outputs."""

class Scenario:
    @staticmethod
    def from_source(source: str, origin: str, base_dir: str | PathLike[str] | None = None) -> Scenario: ...
    @staticmethod
    def from_dict(document: dict[str, Any], origin: str, base_dir: str | PathLike[str] | None = None) -> Scenario: ...
    @staticmethod
    def builtin(name: str) -> Scenario: ...
    @staticmethod
    def builtins() -> list[str]: ...
    @staticmethod
    def load(path: str | PathLike[str]) -> Scenario: ...
    @property
    def name(self) -> str: ...
    @property
    def source(self) -> str: ...
    @property
    def origin(self) -> str: ...
    @property
    def base_dir(self) -> str | None: ...
    def check(self, overrides: Overrides | None = None) -> list[str]: ...
    def run(self, dir: str | PathLike[str], overrides: Overrides | None = None) -> str: ...
    def sweep_len(self, grid: Grid) -> int: ...
    def sweep_csv(self, grid: Grid, cases: list[int] | None = None, threads: int | None = None) -> str: ...

def plot_dir(dir: str | PathLike[str]) -> tuple[list[tuple[str, str, str]], str]: ...

class Simulation:
    def __init__(self, scenario: Scenario, overrides: Overrides | None = None) -> None: ...
    n: int
    time: float
    step_index: int
    steps: int
    dt: float
    done: bool
    order: list[int]
    poses: npt.NDArray[np.float64]
    sensed: npt.NDArray[np.float64]
    agents: list[dict[str, Any]]
    def leader(self, i: int, commands: npt.NDArray[np.float64]) -> dict[str, Any]: ...
    has_safety: bool
    def step(self, commands: npt.NDArray[np.float64], filter: bool) -> None: ...
    def step_by(self, law: Callable[[int, float, npt.NDArray[np.float64], dict[str, Any]], Any]) -> None: ...
    def safety_step(
        self,
    ) -> (
        tuple[
            list[bool], list[str], list[bool], npt.NDArray[np.float64], npt.NDArray[np.float64], list[float]
        ]
        | None
    ): ...
    def errors(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...

def law_paper(
    state: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    dp: npt.NDArray[np.float64],
    ddp: npt.NDArray[np.float64],
    offset: npt.NDArray[np.float64],
    robot_json: str,
    ke: float,
    kz: float,
    variant: str = "paper",
) -> tuple[list[float], list[float], list[float]]: ...
def law_kinematic(
    state: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    dp: npt.NDArray[np.float64],
    offset: npt.NDArray[np.float64],
    ke: float,
) -> tuple[list[float], list[float], list[float]]: ...
def robot_preset(name: str) -> str: ...

class SafetyFilters:
    def __init__(
        self,
        n: int,
        radius: float,
        gain: float = 1.0,
        range: float = ...,
        l: float = 0.1,
        obstacles: npt.NDArray[np.float64] | None = None,
        period: float = 0.01,
        base: str | dict[str, float | str] | None = None,
    ) -> None: ...
    def filter(
        self, t: float, poses: npt.NDArray[np.float64], commands: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], list[str], list[float]]: ...

class TorqueSafetyFilters:
    def __init__(
        self,
        n: int,
        radius: float,
        robots_json: list[str],
        gain: float = 1.0,
        range: float = ...,
        l: float = 0.1,
        obstacles: npt.NDArray[np.float64] | None = None,
    ) -> None: ...
    def filter(
        self, t: float, states: npt.NDArray[np.float64], commands: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], list[str], list[float]]: ...

TORQUE_INNER_RATE: float
TORQUE_ENVELOPE: tuple[float, float, float, float]

# Positional; echelon.bound (_pieces.py) checks the types, holds the defaults.
def bound(
    ke: float, zeta: float, kz: float | None, omega_max: float | None, gamma: float,
    steps: int | None, max_z: float | None, max_e: float | None, ts: float | None, law: str, /
) -> dict[str, Any]: ...
def identify_log(
    *,
    path: str | PathLike[str] | None = None,
    csv: str | None = None,
    agent: int = 1,
    model: str | None = None,
    name: str = "identified",
) -> tuple[str, str]: ...

class BatchEngine:
    @staticmethod
    def bench(
        agents: int, topology: str = "star", drive: str = "torque", dt: float = 0.001, seed: int = 1
    ) -> BatchEngine: ...
    @staticmethod
    def from_scenario(scenario: Scenario, overrides: Overrides | None = None) -> BatchEngine: ...
    n: int
    time: float
    def run(self, steps: int, out: npt.NDArray[np.float64] | None = None) -> None: ...
    def state(self) -> npt.NDArray[np.float64]: ...
    def step(self, state: npt.NDArray[np.float64], steps: int = 1) -> None: ...
    def states(self, out: npt.NDArray[np.float64]) -> None: ...

class VecFormation:
    def __init__(
        self,
        num_envs: int,
        num_agents: int,
        *,
        dt: float | None,
        spacing: float,
        l: float,
        radius: float,
        safety: bool,
        gain: float,
        v_max: float,
        omega_max: float,
        tau_v: float,
        tau_omega: float,
        neighbours: int,
        sense: float,
        weights: tuple[float, float, float],
        max_steps: int,
        speed: tuple[float, float],
        turn: float,
        seed: int,
        float32: bool,
        robot: str | None = None,
        torque_limit: float = 10.0,
        scenario: Scenario | None = None,
        overrides: Overrides | None = None,
        obstacles: int = 0,
        obstacle_radius: tuple[float, float] = (0.1, 0.3),
        seen_obstacles: int | None = None,
    ) -> None: ...
    obs_dim: int
    listed: tuple[int, int]
    action_bound: tuple[float, float]
    model: str
    dt_l: tuple[float, float]
    def reset(self, seed: int, mask: list[bool] | None = None) -> None: ...
    def reset_next(self, mask: list[bool]) -> None: ...
    def observe(self, out: npt.NDArray[np.floating]) -> None: ...
    def step(
        self,
        actions: npt.NDArray[np.floating],
        obs: npt.NDArray[np.floating],
        rewards: npt.NDArray[np.floating],
        changed: npt.NDArray[np.floating],
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_], npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def poses(self) -> npt.NDArray[np.float64]: ...
    def obstacles(self) -> npt.NDArray[np.float64]: ...
    def offsets(self) -> npt.NDArray[np.float64]: ...
    def leaders(self) -> npt.NDArray[np.float64]: ...
    def baseline(
        self, obs: npt.NDArray[np.floating], ke: float, out: npt.NDArray[np.floating], kz: float = 10.0
    ) -> None: ...
