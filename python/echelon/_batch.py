"""The batch engine: N agents stepped in Rust on all cores, the GIL released."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _args, _echelon
from ._scenario import Scenario, _checked, as_scenario


class BatchEngine:
    """N agents of one robot and law, every one following the reference
    (``star``) or each the one before (``chain``), stepped by echelon's batch
    engine (SIMD lanes, all cores) with the GIL released. The states can
    live in a ``(5, n)`` float64 array you own (rows x, y, θ, v, ω):
    ``state = engine.state()`` then ``engine.step(state, steps)`` steps it in
    place, no copy. Or the engine keeps them and writes them into an
    ``(n, 5)`` array when you ask: ``run(steps, out=buffer)``."""

    def __init__(self, inner: Any) -> None:
        self._inner = inner

    @classmethod
    def bench(
        cls, agents: int, topology: str = "star", drive: str = "torque", dt: float = 0.001, seed: int = 1
    ) -> BatchEngine:
        """``echelon bench``'s formation: ``agents`` robots at random poses
        (from ``seed``) behind a circle; ``torque`` (Table I, the paper's law)
        or ``velocity`` (Jackal bases, the kinematic law)."""
        return cls(
            _echelon.BatchEngine.bench(
                _args.integer("agents", agents),
                _args.text("topology", topology),
                _args.text("drive", drive),
                _args.number("dt", dt),
                _args.integer("seed", seed),
            )
        )

    @classmethod
    def from_scenario(cls, scenario: Scenario | str, **overrides: Any) -> BatchEngine:
        """The engine for a scenario whose agents share robot and law and
        form a star or a chain (continuous control, no odometry or safety)."""
        scenario = as_scenario("scenario", scenario)
        return cls(_echelon.BatchEngine.from_scenario(scenario._inner, {**scenario.overrides, **_checked(overrides)}))

    @property
    def n(self) -> int:
        return self._inner.n

    @property
    def time(self) -> float:
        return self._inner.time

    def state(self) -> np.ndarray:
        """A new ``(5, n)`` float64 array, yours, holding the current states
        as rows x, y, θ, v, ω: the buffer :meth:`step` steps in place."""
        return self._inner.state()

    def step(self, state: np.ndarray, steps: int = 1) -> np.ndarray:
        """Steps the states in ``state`` (``(5, n)`` float64, C-contiguous,
        writeable: as :meth:`state` makes it) ``steps`` RK4 steps in place,
        in Rust with the GIL released and no copy: the engine reads and writes
        your array. Returns it. A wrong array raises ``ValueError`` and
        changes nothing. The steps run in chunks with Python's signal
        handlers between them: Ctrl-C raises ``KeyboardInterrupt`` promptly,
        ``state`` (and :attr:`time`) then as of the last finished chunk, the
        same bits as a call of that many steps."""
        self._inner.step(state, _args.integer("steps", steps))
        return state

    def buffer(self) -> np.ndarray:
        """A new ``(n, 5)`` array for :meth:`run` and :meth:`states`."""
        return np.empty((self.n, 5))

    def run(self, steps: int, out: np.ndarray | None = None) -> None:
        """Steps ``steps`` RK4 steps (GIL released); then writes the states
        into ``out`` if given (``(n, 5)`` float64, C-contiguous, writeable;
        a wrong one raises ``ValueError`` before any step). The steps run in
        chunks with Python's signal handlers between them: Ctrl-C raises
        ``KeyboardInterrupt`` promptly, the engine's states then as of the
        last finished chunk (``out`` not written)."""
        self._inner.run(_args.integer("steps", steps), out)

    def states(self, out: np.ndarray) -> np.ndarray:
        """Writes the states into ``out`` (``(n, 5)`` float64, C-contiguous,
        writeable, as :meth:`buffer` makes it); returns it."""
        self._inner.states(out)
        return out
