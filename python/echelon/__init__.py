"""echelon in Python: leader-follower formation control of differential-drive
robots (the paper *Leader-Follower Control with Odometry Error Analysis*),
with the Rust crates' speed.

- :class:`Scenario` and :class:`Run`: the TOML scenarios (built-in, files,
  dicts) run as ``echelon run`` does; tables as pandas DataFrames, figures
  and ``report.html`` through echelon-report;
- :class:`Simulation`: your controller, echelon's robots (``step(commands)``);
- :mod:`echelon.law`, :mod:`echelon.safety`, :func:`bound`, :func:`identify`:
  the pieces as functions on numpy arrays;
- :func:`sweep`: Monte Carlo sweeps on all cores or on a Ray cluster;
- :class:`BatchEngine`: thousands of agents stepped in Rust, the GIL released.

Units are SI and angles radians throughout.
"""

from . import law, safety
from ._batch import BatchEngine
from ._echelon import ScenarioError, SimulationError, __version__
from ._pieces import bound, identify
from ._scenario import Run, Scenario, builtins
from ._simulation import Simulation
from ._sweep import Sweep, sweep

__all__ = [
    "BatchEngine",
    "Run",
    "Scenario",
    "ScenarioError",
    "Simulation",
    "SimulationError",
    "Sweep",
    "__version__",
    "bound",
    "builtins",
    "identify",
    "law",
    "safety",
    "sweep",
]
