"""Scenarios and runs (``echelon run``, ``echelon plot``) from Python."""

from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
import weakref
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from . import _args, _echelon

#: The keyword arguments that override a scenario's settings, as
#: ``echelon run``'s flags do: ``dt`` (RK4 step, s), ``duration`` (s),
#: ``log_dt`` (logging period, s; 0 logs every step), ``law`` (``"paper"``
#: or ``"complete"`` for every agent) and ``seed``.
OVERRIDES = ("dt", "duration", "log_dt", "law", "seed")


def read_csv(source: Any) -> pd.DataFrame:
    """A table echelon wrote, its numbers exactly as written: pandas 3 parses
    floats round-trip, pandas 2 (the last on Python 3.10) only when asked
    (its default was 1 ulp off some written values)."""
    if int(pd.__version__.split(".")[0]) < 3:
        return pd.read_csv(source, float_precision="round_trip")
    return pd.read_csv(source)


def _checked(overrides: dict[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(overrides) - set(OVERRIDES))
    if unknown:
        raise TypeError(
            f"unknown override(s) {', '.join(unknown)}; the overrides are {', '.join(OVERRIDES)}"
        )
    out: dict[str, Any] = {}
    for k, v in overrides.items():
        if v is None:
            continue
        if k == "law":
            out[k] = _args.text(k, v)
        elif k == "seed":
            out[k] = _args.integer(k, v)
        else:
            out[k] = _args.number(k, v)
    return out


def as_scenario(name: str, scenario: Any) -> Scenario:
    """``scenario``: a :class:`Scenario`, or a built-in scenario's name."""
    if isinstance(scenario, str):
        return Scenario.builtin(scenario)
    if not isinstance(scenario, Scenario):
        raise TypeError(
            f"{name} must be an echelon.Scenario or a built-in scenario's name, got {_args.describe(scenario)}"
        )
    return scenario


def builtins() -> list[str]:
    """The names of the built-in scenarios (``echelon scenarios``)."""
    return list(_echelon.Scenario.builtins())


class Scenario:
    """A scenario: a parsed TOML document and the overrides to run it with.

    Errors in the document raise :class:`echelon.ScenarioError`, whose
    ``file``, ``line``, ``column`` and ``field`` say where.
    """

    def __init__(self, inner: _echelon.Scenario, **overrides: Any) -> None:
        self._inner = inner
        self._overrides = _checked(overrides)
        # Build once: a scenario that cannot run fails here, not later.
        self._warnings = inner.check(self._overrides)

    @classmethod
    def builtin(cls, name: str, **overrides: Any) -> Scenario:
        """A built-in scenario by name (see :func:`echelon.builtins`)."""
        return cls(_echelon.Scenario.builtin(_args.text("name", name)), **overrides)

    @classmethod
    def load(cls, path: str | os.PathLike[str], **overrides: Any) -> Scenario:
        """A scenario file."""
        return cls(_echelon.Scenario.load(_args.path("path", path)), **overrides)

    @classmethod
    def from_toml(
        cls,
        text: str,
        origin: str = "<toml>",
        base_dir: str | os.PathLike[str] | None = None,
        **overrides: Any,
    ) -> Scenario:
        """A scenario from TOML text; ``origin`` names it in errors."""
        base = _args.optional_path("base_dir", base_dir)
        source = _args.text("text", text)
        return cls(_echelon.Scenario.from_source(source, _args.text("origin", origin), base), **overrides)

    @classmethod
    def from_dict(
        cls,
        document: dict[str, Any],
        origin: str = "<dict>",
        base_dir: str | os.PathLike[str] | None = None,
        **overrides: Any,
    ) -> Scenario:
        """A scenario from the TOML document as a dict (as ``tomllib.load``
        gives it). An error in it points into the dict: its
        :class:`echelon.ScenarioError` has ``file`` = ``origin``, ``line`` =
        ``column`` = 0, ``field`` the dict path with indices as in the dict
        (from 0: ``agents[1].offset.x`` is ``document["agents"][1]["offset"]["x"]``)
        and ``path`` the same as a tuple of keys and indices: a value out of
        range, NaN or infinite where a finite number is needed, or one TOML
        has no form for (None, a set, …). numpy scalars and arrays are taken
        as their ``tolist()``. A ``document`` that is not a dict is a
        ``TypeError``."""
        if not isinstance(document, dict):
            raise TypeError(
                f"document: not a scenario document: a dict of the scenario's tables, not a {type(document).__name__}"
            )
        base = _args.optional_path("base_dir", base_dir)
        origin = _args.text("origin", origin)
        try:
            return cls(_echelon.Scenario.from_dict(document, origin, base), **overrides)
        except _echelon.ScenarioError as e:
            if e.file != origin:
                raise  # not in the document: an override's, a waypoints file's
            raise _dict_error(e, document, origin) from None

    @property
    def name(self) -> str:
        return self._inner.name

    @property
    def source(self) -> str:
        """The TOML source."""
        return self._inner.source

    @property
    def origin(self) -> str:
        return self._inner.origin

    @property
    def overrides(self) -> dict[str, Any]:
        return dict(self._overrides)

    @property
    def warnings(self) -> list[str]:
        """Values that are allowed but outside their usual range."""
        return list(self._warnings)

    def with_overrides(self, **overrides: Any) -> Scenario:
        """The same scenario with more overrides."""
        return Scenario(self._inner, **{**self._overrides, **_checked(overrides)})

    def run(self, out: str | os.PathLike[str] | None = None, **overrides: Any) -> Run:
        """Runs the scenario as ``echelon run`` does, writing its files into
        ``out`` (a temporary directory, removed with the :class:`Run`, when
        None). Raises :class:`echelon.SimulationError` when the run diverges."""
        ov = {**self._overrides, **_checked(overrides)}
        if out is None:
            directory = Path(tempfile.mkdtemp(prefix=f"echelon-{self.name}-"))
            temporary = True
        else:
            directory = _args.path("out", out)
            temporary = False
        try:
            summary = self._inner.run(directory, ov)
        except BaseException:
            if temporary:
                shutil.rmtree(directory, ignore_errors=True)
            raise
        return Run(directory, json.loads(summary), temporary=temporary)

    def __reduce__(self) -> tuple[Any, ...]:
        return (_restore, (self._inner, self._overrides))

    def __repr__(self) -> str:
        ov = "".join(f", {k}={v!r}" for k, v in self._overrides.items())
        return f"Scenario({self.name!r} from {self.origin!r}{ov})"


def _dict_path(document: Any, field: str) -> tuple[str | int, ...]:
    """The path into ``document`` of a scenario error's ``field`` (the file's
    dotted path, e.g. ``agents[3].offset.x``, agents counting from 1): keys
    matched against the dict's own (a key may hold a dot), indices from 0."""
    path: list[str | int] = []
    node, rest = document, field
    while rest:
        if rest.startswith("["):
            close = rest.find("]")
            if close < 0 or not rest[1:close].isdigit():
                path.append(rest)
                break
            index = int(rest[1:close]) - 1
            path.append(index)
            node = node[index] if isinstance(node, list) and 0 <= index < len(node) else None
            rest = rest[close + 1 :]
            continue
        rest = rest.removeprefix(".")
        key = None
        if isinstance(node, dict):
            for k in sorted((k for k in node if isinstance(k, str)), key=len, reverse=True):
                if rest.startswith(k) and (len(rest) == len(k) or rest[len(k)] in ".["):
                    key = k
                    break
        if key is None:  # not in the dict (a missing field): up to the next separator
            key = re.match(r"[^.\[]*", rest).group(0)  # type: ignore[union-attr]
        path.append(key)
        node = node.get(key) if isinstance(node, dict) else None
        rest = rest[len(key) :]
        if not key and rest:  # nothing consumed: keep the rest whole
            path[-1] = rest
            break
    return tuple(path)


def _dotted(path: tuple[str | int, ...]) -> str:
    """``agents[1].offset.x``; a key that is not a plain name as ``["a.b"]``."""
    out = ""
    for seg in path:
        if isinstance(seg, int):
            out += f"[{seg}]"
        elif re.fullmatch(r"[A-Za-z0-9_-]+", seg):
            out += f".{seg}" if out else seg
        else:
            out += f"[{json.dumps(seg, ensure_ascii=False)}]"
    return out


def _dict_error(e: Any, document: Any, origin: str) -> Any:
    """A scenario error in a dict document, pointing into the dict."""
    path = _dict_path(document, e.field) if e.field else ()
    field = _dotted(path)
    text = f"{origin}: {field}: {e.message}" if field else f"{origin}: {e.message}"
    err = _echelon.ScenarioError(text)
    err.file, err.line, err.column = origin, 0, 0
    err.field, err.path, err.message = field, path, e.message
    return err


def _restore(inner: _echelon.Scenario, overrides: dict[str, Any]) -> Scenario:
    return Scenario(inner, **overrides)


class Run:
    """A finished run: the files ``echelon run`` writes, read back.

    ``trajectory`` has ``trajectory.csv``'s columns (one row per agent per
    logged instant; ``agent`` counts from 1); ``agents`` has the same per
    agent as numpy arrays; ``summary`` is ``summary.json``; ``odometry`` and
    ``safety`` are the tables of runs that dead-reckon or filter, else None.
    """

    def __init__(self, directory: Path, summary: dict[str, Any], temporary: bool = False) -> None:
        self.dir = Path(directory)
        self.summary = summary
        self._tables: dict[str, pd.DataFrame | None] = {}
        if temporary:
            weakref.finalize(self, shutil.rmtree, str(self.dir), True)

    def _table(self, name: str) -> pd.DataFrame | None:
        if name not in self._tables:
            path = self.dir / f"{name}.csv"
            self._tables[name] = read_csv(path) if path.exists() else None
        return self._tables[name]

    @property
    def trajectory(self) -> pd.DataFrame:
        table = self._table("trajectory")
        assert table is not None, "every run writes trajectory.csv"
        return table

    @property
    def reference(self) -> pd.DataFrame | None:
        return self._table("reference")

    @property
    def integrals(self) -> pd.DataFrame | None:
        return self._table("integrals")

    @property
    def odometry(self) -> pd.DataFrame | None:
        return self._table("odometry")

    @property
    def safety(self) -> pd.DataFrame | None:
        return self._table("safety")

    @property
    def agents(self) -> list[dict[str, np.ndarray]]:
        """Per agent (in order), each trajectory column as a numpy array."""
        t = self.trajectory
        return [
            {c: group[c].to_numpy() for c in t.columns if c != "agent"}
            for _, group in t.groupby("agent", sort=True)
        ]

    @property
    def final_errors(self) -> list[float]:
        """Each agent's final ‖e‖, m (``summary.json``'s ``final_error``)."""
        return [a["final_error"] for a in self.summary["agents"]]

    def plot(self, files: bool = False) -> dict[str, Any]:
        """The run's figures (``echelon plot``: paths, errors, signals, and
        safety when filtered), written as SVG and PNG into the run's
        directory with ``report.html``. Returns them by name as matplotlib
        figures, or with ``files=True`` as their PNG paths."""
        files = _args.flag("files", files)
        figures, _report = _echelon.plot_dir(self.dir)
        if files:
            return {name: Path(png) for name, _svg, png in figures}
        import matplotlib.image as mpimg
        import matplotlib.pyplot as plt

        out = {}
        for name, _svg, png in figures:
            image = mpimg.imread(png)
            h, w = image.shape[:2]
            fig = plt.figure(figsize=(w / 100, h / 100), dpi=100)
            ax = fig.add_axes((0, 0, 1, 1))
            ax.imshow(image)
            ax.set_axis_off()
            plt.close(fig)
            out[name] = fig
        return out

    def report(self, path: str | os.PathLike[str]) -> Path:
        """Writes the self-contained ``report.html`` (figures and replay) to
        ``path``; returns it."""
        target = _args.path("path", path)
        _figures, report = _echelon.plot_dir(self.dir)
        if target.resolve() != Path(report).resolve():
            shutil.copyfile(report, target)
        return target

    def __repr__(self) -> str:
        return f"Run({self.summary['scenario']!r}, dir={str(self.dir)!r})"
