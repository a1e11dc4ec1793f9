"""Monte Carlo sweeps over odometry errors × fix intervals × seeds
(``echelon sweep``), on all local cores or as Ray tasks."""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any, Iterable, Mapping

import pandas as pd

from . import _echelon
from ._scenario import Scenario, read_csv

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
        p = Path(path)
        p.write_bytes(self.csv.encode())
        return p

    def __repr__(self) -> str:
        return f"Sweep({len(self.table)} runs)"


def _arguments(
    scenario: Scenario, grid: Mapping[str, Any] | None, seeds: int | Iterable[int], first_seed: int,
    gamma: float, transient: float | None,
) -> dict[str, Any]:
    g = dict(GRID_DEFAULTS)
    unknown = sorted(set(grid or {}) - set(g))
    if unknown:
        raise TypeError(f"unknown grid key(s) {', '.join(unknown)}; the keys are {', '.join(g)}")
    g.update(grid or {})
    listed = lambda v: [v] if isinstance(v, (int, float)) else list(v)  # noqa: E731
    if isinstance(seeds, int) and seeds < 1:
        raise ValueError(
            f"seeds: {seeds} seeds per combination: the number of runs of each combination "
            "(seeds first_seed, first_seed + 1, …) must be ≥ 1, or give a list of seeds"
        )
    seed_list = list(range(first_seed, first_seed + seeds)) if isinstance(seeds, int) else list(seeds)
    ov = scenario.overrides
    return {
        "zeta": [float(x) for x in listed(g["zeta"])],
        "zeta_model": g["zeta_model"],
        "ed": [float(x) for x in listed(g["ed"])],
        "eb": [float(x) for x in listed(g["eb"])],
        "slip": [float(x) for x in listed(g["slip"])],
        "fix_every": [int(x) for x in listed(g["fix_every"])],
        "seeds": [int(s) for s in seed_list],
        "gamma": float(gamma),
        "transient": transient,
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
    if isinstance(scenario, str):
        scenario = Scenario.builtin(scenario)
    args = _arguments(scenario, grid, seeds, first_seed, gamma, transient)
    inner = scenario._inner
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
