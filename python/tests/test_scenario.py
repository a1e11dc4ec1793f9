"""Scenarios and runs: the same files and numbers as `echelon run`, errors
with their place in the file."""

from __future__ import annotations

import copy
import json
import pickle
import subprocess

import numpy as np
import pandas as pd
import pytest

import echelon
from conftest import builtin_document


def test_a_builtin_run_matches_the_cli_bit_for_bit(echelon_cli, tmp_path):
    out = tmp_path / "cli"
    subprocess.run(
        [str(echelon_cli), "run", "lemniscate-wedge", "--duration", "5", "--out", str(out), "-q"],
        check=True,
    )
    run = echelon.Scenario.builtin("lemniscate-wedge", duration=5).run(tmp_path / "py")
    cli_summary = json.loads((out / "summary.json").read_text())
    assert run.summary == cli_summary
    assert run.final_errors == [a["final_error"] for a in cli_summary["agents"]]
    for name in ["trajectory.csv", "reference.csv", "integrals.csv", "summary.json"]:
        assert (tmp_path / "py" / name).read_bytes() == (out / name).read_bytes(), name


def test_the_trajectory_table_and_per_agent_arrays_agree():
    run = echelon.Scenario.builtin("circle-pentagon", duration=2).run()
    t = run.trajectory
    assert list(t.columns[:7]) == ["t", "agent", "x", "y", "theta", "v", "omega"]
    assert sorted(t["agent"].unique()) == [1, 2, 3, 4]
    assert len(run.agents) == 4
    for k, a in enumerate(run.agents, start=1):
        rows = t[t["agent"] == k]
        np.testing.assert_array_equal(a["x"], rows["x"].to_numpy())
        np.testing.assert_array_equal(a["t"], rows["t"].to_numpy())
        # Final pose of summary.json is the last logged row.
        final = run.summary["agents"][k - 1]["final_pose"]
        assert (a["x"][-1], a["y"][-1]) == (final["x"], final["y"])
    assert run.odometry is None and run.safety is None


def test_odometry_and_safety_tables_when_present():
    fix = echelon.Scenario.builtin("fix-study", duration=1).run()
    assert isinstance(fix.odometry, pd.DataFrame) and len(fix.odometry) > 0
    crossing = echelon.Scenario.builtin("crossing", duration=1).run()
    assert isinstance(crossing.safety, pd.DataFrame) and len(crossing.safety) > 0
    assert "safety" in crossing.summary


def test_overrides_as_keyword_arguments():
    base = echelon.Scenario.builtin("circle-pentagon")
    s = base.with_overrides(duration=0.5, dt=0.002, log_dt=0.1, law="complete", seed=3)
    run = s.run()
    assert run.summary["dt"] == 0.002
    assert run.summary["steps"] == 250
    assert list(run.trajectory["t"].unique()) == pytest.approx([0, 0.1, 0.2, 0.3, 0.4, 0.5])
    with pytest.raises(TypeError, match="unknown override"):
        base.with_overrides(speed=2)
    with pytest.raises(ValueError, match="dt"):
        base.run(dt=-1)


def test_from_dict_runs_the_same_as_the_file():
    doc = builtin_document("circle-pentagon")
    a = echelon.Scenario.from_dict(doc, duration=1).run()
    b = echelon.Scenario.builtin("circle-pentagon", duration=1).run()
    assert a.summary == b.summary
    pd.testing.assert_frame_equal(a.trajectory, b.trajectory)


def test_load_a_file(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(echelon.Scenario.builtin("experiment-circle").source)
    s = echelon.Scenario.load(path, duration=0.5)
    assert s.name == "experiment-circle"
    assert s.run().summary["steps"] > 0


def test_scenario_errors_carry_file_line_column_and_field(tmp_path):
    source = echelon.Scenario.builtin("circle-pentagon").source
    lines = source.splitlines()
    k = next(i for i, l in enumerate(lines) if l.startswith("ke = "))
    lines[k] = "ke = -1.5"
    path = tmp_path / "bad.toml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(echelon.ScenarioError) as info:
        echelon.Scenario.load(path)
    e = info.value
    assert (e.file, e.line, e.column) == (str(path), k + 1, 6)
    assert e.field == "control.ke"
    assert str(e).startswith(f"{path}:{k + 1}:6: control.ke: ")
    assert isinstance(e, ValueError)


def test_a_dict_error_is_a_type_error_when_not_a_document():
    for document in [[], "[sim]\ndt = 0.01\n", None, 3.0]:
        with pytest.raises(TypeError, match="not a scenario document"):
            echelon.Scenario.from_dict(document)


def _numbers(node, path=()):
    """The path of every number in a document."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _numbers(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _numbers(v, path + (i,))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield path


@pytest.mark.parametrize("name", echelon.builtins())
def test_a_nan_anywhere_in_a_dict_is_a_scenario_error_at_its_path(name):
    # A NaN reaches the scenario's own checks (as `x = nan` in a file does),
    # which name its place: no number of any built-in takes one.
    base = builtin_document(name)
    paths = list(_numbers(base))
    assert len(paths) > 5
    for where in paths:
        doc = copy.deepcopy(base)
        _set(doc, where, float("nan"))
        with pytest.raises(echelon.ScenarioError) as info:
            echelon.Scenario.from_dict(doc, origin="d")
        e = info.value
        assert e.path == where, (where, str(e))
        # "NaN must be a finite number", or a NaN where a whole number goes.
        assert "NaN" in e.message, str(e)
        assert (e.file, e.line, e.column) == ("d", 0, 0)


@pytest.mark.parametrize(
    "value, needle",
    [
        (None, "None"),
        ({1, 2}, "set"),
        (object(), "object"),
        (2**70, "64 bits"),
        (b"0.5", "bytes"),
    ],
)
@pytest.mark.parametrize("where", [("control", "ke"), ("agents", 2, "offset", "x"), ("sim", "extra", 1)])
def test_a_value_toml_cannot_hold_is_a_scenario_error_at_its_path(value, needle, where):
    doc = builtin_document("circle-pentagon")
    doc["sim"]["extra"] = [1.0, 2.0]
    _set(doc, where, value)
    with pytest.raises(echelon.ScenarioError) as info:
        echelon.Scenario.from_dict(doc)
    assert info.value.path == where, str(info.value)
    assert needle in info.value.message


def test_a_list_that_holds_itself_is_refused_not_recursed_forever():
    doc = builtin_document("circle-pentagon")
    loop: list = []
    loop.append(loop)
    doc["agents"][0]["offset"]["x"] = loop
    with pytest.raises(echelon.ScenarioError, match="nested deeper"):
        echelon.Scenario.from_dict(doc)


def test_numpy_numbers_in_a_dict_are_their_values():
    doc = builtin_document("circle-pentagon")
    doc["control"]["ke"] = np.float64(doc["control"]["ke"])
    doc["agents"][1]["offset"] = {k: np.float32(v) for k, v in doc["agents"][1]["offset"].items()}
    doc["agents"][2]["offset"]["x"] = np.array(doc["agents"][2]["offset"]["x"])
    a = echelon.Scenario.from_dict(doc, duration=0.5).run()
    plain = builtin_document("circle-pentagon")
    plain["agents"][1]["offset"] = {k: float(np.float32(v)) for k, v in plain["agents"][1]["offset"].items()}
    b = echelon.Scenario.from_dict(plain, duration=0.5).run()
    assert a.summary == b.summary


def _set(doc: dict, path: tuple, value) -> None:
    node = doc
    for k in path[:-1]:
        node = node[k]
    if value is _DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value


_DELETE = object()

# (where, what): a wrong value at `where` in circle-pentagon's document (or
# none: a missing field), each a different check of the scenario's.
_WRONG = [
    (("control", "ke"), -1.5),  # a gain must be > 0
    (("control", "kz"), "ten"),  # a type error, found while parsing
    (("sim", "dt"), 0.0),
    (("agents", 2, "offset", "x"), -5.0),  # L_X > 0 (eq. 4)
    (("agents", 0, "start", "x"), "left"),
    (("agents", 3, "leader"), 9),  # no agent 9
    (("agents", 1, "start"), _DELETE),  # missing field
    (("agents", 1, "control", "ke"), -2.0),  # an agent's own gains
    (("robots", "heavy.bot", "mass"), -27.0),  # a key with a dot
    (("robots", "heavy.bot", "wheel_radius"), "big"),
    (("agents", 0, "max_accel"), -1.0),
    (("agents", 2, "wrong_key"), 1.0),  # an unknown field
]


@pytest.mark.parametrize("where, value", _WRONG, ids=lambda w: ".".join(map(str, w)) if isinstance(w, tuple) else None)
def test_a_dict_error_points_into_the_dict(where, value):
    doc = builtin_document("circle-pentagon")
    doc["robots"] = {"heavy.bot": {"preset": "agent1"}}
    for a in doc["agents"]:
        a["robot"] = "heavy.bot"
    doc["agents"][1]["control"] = {"ke": 1.0}
    echelon.Scenario.from_dict(doc)  # the document itself is fine
    _set(doc, where, value)
    with pytest.raises(echelon.ScenarioError) as info:
        echelon.Scenario.from_dict(doc, origin="my-dict")
    e = info.value
    assert (e.file, e.line, e.column) == ("my-dict", 0, 0)
    assert e.path == where, (e.path, str(e))
    # The path indexes the dict (what is there, or the parent of a missing field).
    node = doc
    for k in e.path[:-1]:
        node = node[k]
    assert value is _DELETE or node[e.path[-1]] == value
    expected = "".join(
        f"[{k}]" if isinstance(k, int) else (f'["{k}"]' if "." in k else (f".{k}" if i else k))
        for i, k in enumerate(where)
    )
    assert e.field == expected
    assert str(e) == f"my-dict: {expected}: {e.message}"
    assert isinstance(e, ValueError)


def test_a_dict_error_from_an_override_keeps_its_own_place():
    doc = builtin_document("circle-pentagon")
    with pytest.raises(ValueError, match="dt"):
        echelon.Scenario.from_dict(doc, dt=-1.0)


def test_unknown_builtin_and_parse_errors():
    with pytest.raises(echelon.ScenarioError, match="built-ins: .*circle-pentagon"):
        echelon.Scenario.builtin("no-such")
    with pytest.raises(echelon.ScenarioError) as info:
        echelon.Scenario.from_toml("[sim]\ndt = \n", origin="inline.toml")
    assert info.value.file == "inline.toml" and info.value.line == 2


def test_scenarios_pickle():
    s = echelon.Scenario.builtin("fix-study", duration=0.5)
    t = pickle.loads(pickle.dumps(s))
    assert (t.name, t.source, t.overrides) == (s.name, s.source, s.overrides)


def test_plot_and_report(tmp_path):
    run = echelon.Scenario.builtin("circle-pentagon", duration=1).run(tmp_path / "run")
    files = run.plot(files=True)
    assert {"paths", "errors", "signals"} <= set(files)
    assert all(p.read_bytes().startswith(b"\x89PNG") for p in files.values())
    figures = run.plot()
    assert figures["paths"].get_axes()
    report = run.report(tmp_path / "r.html")
    assert report.read_text().lstrip().lower().startswith("<!doctype html")
