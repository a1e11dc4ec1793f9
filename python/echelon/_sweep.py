"""Monte Carlo sweeps over odometry errors × fix intervals × seeds
(``echelon sweep``), on all local cores or as Ray tasks."""

from __future__ import annotations

import io
import numbers
import os
from pathlib import Path
from typing import Any, Iterable, Mapping

import pandas as pd

from . import _args, _echelon
from ._scenario import Scenario, as_scenario, read_csv

#: A sweep grid's keys and ``echelon sweep``'s defaults.
GRID_DEFAULTS: dict[str, Any] = {
    "zeta": [1e-5],
    "zeta_model": "wheels",
    "ed": [1.0],
    "eb": [1.0],
    "slip": [0.0],
    "fix_every": [10, 20, 50, 100, 200, 500],
}


class Sweep:
    """A sweep's ``sweep.csv``: ``csv`` (its exact text) and ``table`` (a
    DataFrame of it)."""

    def __init__(self, csv: str) -> None:
        self.csv = csv
        self._table: pd.DataFrame | None = None

    @property
    def table(self) -> pd.DataFrame:
        if self._table is None:
            self._table = read_csv(io.StringIO(self.csv))
        return self._table

    def write(self, path: str | os.PathLike[str]) -> Path:
        """Writes ``sweep.csv``'s bytes to ``path``."""
        p = _args.path("path", path)
        p.write_bytes(self.csv.encode())
        return p

    def __repr__(self) -> str:
        return f"Sweep({len(self.table)} runs)"


def _listed(key: str, value: Any) -> list[Any]:
    """A grid value as a list: one number, or a list, tuple, range or numpy
    array of them (not text, which is no list of numbers)."""
    if isinstance(value, numbers.Real):
        return [value]
    if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
        raise TypeError(f"{key}: {value!r} is not a number or a list of numbers")
    return list(value.tolist() if hasattr(value, "tolist") else value)


def _numbers(key: str, value: Any) -> list[float]:
    out = []
    for x in _listed(key, value):
        if not isinstance(x, numbers.Real):
            raise TypeError(f"{key}: {x!r} is not a number")
        out.append(float(x))
    return out


def _whole_numbers(key: str, value: Any) -> list[int]:
    """Whole numbers in [0, 2**64) (``10.0`` is 10; ``10.7`` is refused, not cut)."""
    out = []
    for x in _listed(key, value):
        if isinstance(x, numbers.Real) and not isinstance(x, numbers.Integral):
            if not float(x).is_integer():
                raise ValueError(f"{key}: {x!r} is not a whole number")
            x = int(x)
        if not isinstance(x, numbers.Integral):
            raise TypeError(f"{key}: {x!r} is not a whole number")
        if not 0 <= x < 2**64:
            raise ValueError(f"{key}: {x} must be a whole number in [0, 2**64)")
        out.append(int(x))
    return out


def _arguments(
    scenario: Scenario, grid: Mapping[str, Any] | None, seeds: int | Iterable[int], first_seed: int,
    gamma: float, transient: float | None,
) -> dict[str, Any]:
    if grid is not None and not isinstance(grid, Mapping):
        raise TypeError(f"grid must be a dict of grid keys ({', '.join(GRID_DEFAULTS)}), got {_args.describe(grid)}")
    g = dict(GRID_DEFAULTS)
    unknown = sorted(set(grid or {}) - set(g))
    if unknown:
        raise TypeError(f"unknown grid key(s) {', '.join(unknown)}; the keys are {', '.join(g)}")
    g.update(grid or {})
    if (
        isinstance(first_seed, bool)
        or not isinstance(first_seed, numbers.Integral)
        or not 0 <= first_seed < 2**64
    ):
        raise ValueError(f"first_seed: {first_seed!r} must be a whole number in [0, 2**64)")
    if isinstance(seeds, numbers.Integral) and not isinstance(seeds, bool):
        if seeds < 1:
            raise ValueError(
                f"seeds: {seeds} seeds per combination: the number of runs of each combination "
                "(seeds first_seed, first_seed + 1, …) must be ≥ 1, or give a list of seeds"
            )
        if first_seed + seeds > 2**64:
            raise ValueError(
                f"seeds: {seeds} seeds from first_seed = {first_seed} go past the last seed, 2**64 − 1"
            )
        seed_list = list(range(first_seed, first_seed + seeds))
    else:
        seed_list = _whole_numbers("seeds", seeds)
    if not isinstance(g["zeta_model"], str):
        raise TypeError(f"zeta_model: {g['zeta_model']!r} (\"wheels\" or \"worst-case\")")
    ov = scenario.overrides
    return {
        "zeta": _numbers("zeta", g["zeta"]),
        "zeta_model": g["zeta_model"],
        "ed": _numbers("ed", g["ed"]),
        "eb": _numbers("eb", g["eb"]),
        "slip": _numbers("slip", g["slip"]),
        "fix_every": _whole_numbers("fix_every", g["fix_every"]),
        "seeds": seed_list,
        "gamma": _args.number("gamma", gamma),
        "transient": _args.optional_number("transient", transient),
        "dt": ov.get("dt"),
        "duration": ov.get("duration"),
    }


def _cases(inner: Any, args: dict[str, Any], cases: list[int]) -> str:
    """One Ray task: the rows of ``cases``, on one thread (Ray schedules cores)."""
    return inner.sweep_csv(args, cases=cases, threads=1)


def sweep(
    scenario: Scenario | str,
    grid: Mapping[str, Any] | None = None,
    seeds: int | Iterable[int] = 4,
    executor: str | None = None,
    *,
    first_seed: int = 0,
    gamma: float = 0.99,
    transient: float | None = None,
    threads: int | None = None,
    tasks: int | None = None,
) -> Sweep:
    """Runs ``scenario`` over every combination of ``grid`` × ``seeds``
    (``echelon sweep``): ``grid`` may set ``zeta`` (m per sample),
    ``zeta_model`` (``wheels`` or ``worst-case``), ``ed``, ``eb`` (wheel
    diameter and wheelbase ratios), ``slip`` (m²/m) and ``fix_every`` (N);
    ``seeds`` is a count (from ``first_seed``) or a list. The scenario's
    ``dt`` and ``duration`` overrides apply; statistics start at
    ``transient`` s (default half the duration).

    ``executor=None`` runs on all local cores (``threads`` to limit them);
    ``executor="ray"`` runs the cases as Ray tasks (``tasks`` of them,
    default twice the cluster's CPUs) on the cluster ``ray.init`` connected
    to; the table is byte for byte the local one."""
    scenario = as_scenario("scenario", scenario)
    args = _arguments(scenario, grid, seeds, first_seed, gamma, transient)
    inner = scenario._inner
    threads = _args.optional_integer("threads", threads, low=1)
    tasks = _args.optional_integer("tasks", tasks, low=1)
    if executor is None:
        return Sweep(inner.sweep_csv(args, threads=threads))
    if executor != "ray":
        raise ValueError(f"executor: `{executor}` (None for local cores, or \"ray\")")
    import ray

    if not ray.is_initialized():
        ray.init()
    total = inner.sweep_len(args)
    if tasks is None:
        tasks = max(1, 2 * int(ray.cluster_resources().get("CPU", 1)))
    tasks = max(1, min(tasks, total))
    chunks = [list(range(total))[k::tasks] for k in range(tasks)]
    remote = ray.remote(num_cpus=1)(_cases)
    futures = [remote.remote(inner, args, chunk) for chunk in chunks]
    parts = ray.get(futures)
    # Rows back in grid order: chunk k holds cases k, k + tasks, ...
    lines_by_chunk = [p.splitlines(keepends=True) for p in parts]
    rows = [""] * total
    for k, lines in enumerate(lines_by_chunk):
        for j, line in enumerate(lines):
            rows[k + j * tasks] = line
    return Sweep(_echelon.SWEEP_HEADER + "\n" + "".join(rows))
