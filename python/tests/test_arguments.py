"""Every public function given an argument of the wrong type (text, None, a
list of text, NaN where a finite number is needed, a wrong array) raises
TypeError or ValueError whose message starts by naming that argument, and
nothing else: the same call with the good value goes through."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import echelon
from conftest import builtin_document

NAN = float("nan")
#: Stands for an array like the good one, every value NaN.
NAN_ARRAY = object()

TEXT = [None, 1, ["a"]]
NUMBER = ["1", None, ["a"], b"1", True]
FINITE = NUMBER + [NAN]
OPTIONAL_FINITE = ["1", ["a"], NAN]
INT = ["1", None, 1.5, ["a"], True, -1]
OPTIONAL_INT = ["1", 1.5, ["a"], -1]
FLAG = ["yes", None, 1]
OPTIONAL_FLAG = ["yes", 1]
PATH = [None, 1, ["a"]]
OPTIONAL_PATH = [1, ["a"]]
ARRAY = ["abc", None, [["a", "b"]], [[1.0, None]], NAN_ARRAY]
OPTIONAL_ARRAY = ["abc", [["a", "b"]], NAN_ARRAY]
#: An array the call writes into: converting it would lose what is written.
BUFFER = ["abc", None, [["a"]], 3.0, "float32", "transposed", "read-only"]
OPTIONAL_BUFFER = [b for b in BUFFER if b is not None]
SCENARIO = [None, 1, ["a"]]
#: None is an override's default (the scenario's own value).
OVERRIDES = {
    "dt": OPTIONAL_FINITE + [b"1", True],
    "duration": OPTIONAL_FINITE,
    "law": [1, ["a"]],
    "seed": OPTIONAL_INT + [True],
}


def _star() -> echelon.Scenario:
    """circle-pentagon with every agent following the reference: a batch engine's formation."""
    doc = builtin_document("circle-pentagon")
    for a in doc["agents"]:
        a["leader"] = "reference"
    return echelon.Scenario.from_dict(doc)


def engine() -> echelon.BatchEngine:
    return echelon.BatchEngine.bench(3, seed=5)


def simulation() -> echelon.Simulation:
    return echelon.Simulation("circle-pentagon")


LEADER = {"p": [0.3, 0.0], "dp": [0.5, 0.0], "ddp": [0.0, 0.0], "lx": 0.3, "ly": 0.0}
POSES = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
STATES = np.array([[0.0, 0.0, 0.0, 0.1, 0.0], [1.0, 0.0, 0.0, 0.0, 0.0]])
COMMANDS = np.array([[0.1, 0.0], [0.2, 0.0]])
OBSTACLES = np.array([[5.0, 5.0, 0.5]])
SHORT = {"duration": 0.05}


#: (what, make the callable, good arguments, {argument: wrong values}).
API: list[tuple[str, Callable[[], Callable[..., Any]], dict[str, Any], dict[str, list[Any]]]] = [
    (
        "BatchEngine.bench",
        lambda: echelon.BatchEngine.bench,
        dict(agents=3, topology="chain", drive="velocity", dt=0.001, seed=1),
        dict(agents=INT, topology=TEXT, drive=TEXT, dt=FINITE, seed=INT),
    ),
    (
        "BatchEngine.from_scenario",
        lambda: echelon.BatchEngine.from_scenario,
        dict(scenario=_star(), dt=0.001, duration=1.0, law="paper", seed=3),
        dict(scenario=SCENARIO, **OVERRIDES),
    ),
    (
        "BatchEngine.step",
        lambda: engine().step,
        dict(state=engine().state(), steps=2),
        dict(state=BUFFER, steps=INT),
    ),
    (
        "BatchEngine.run",
        lambda: engine().run,
        dict(steps=2, out=np.zeros((3, 5))),
        dict(steps=INT, out=OPTIONAL_BUFFER),
    ),
    ("BatchEngine.states", lambda: engine().states, dict(out=np.zeros((3, 5))), dict(out=BUFFER)),
    (
        "Scenario.builtin",
        lambda: echelon.Scenario.builtin,
        dict(name="circle-pentagon", dt=0.001, duration=1.0, law="paper", seed=3),
        dict(name=TEXT, **OVERRIDES),
    ),
    (
        "Scenario.load",
        lambda: (Path("s.toml").write_text(echelon.Scenario.builtin("circle-pentagon").source), echelon.Scenario.load)[1],
        dict(path="s.toml", dt=0.001, duration=1.0, law="paper", seed=3),
        dict(path=PATH, **OVERRIDES),
    ),
    (
        "Scenario.from_toml",
        lambda: echelon.Scenario.from_toml,
        dict(text=echelon.Scenario.builtin("circle-pentagon").source, origin="x.toml", base_dir="."),
        dict(text=TEXT, origin=TEXT, base_dir=OPTIONAL_PATH),
    ),
    (
        "Scenario.from_dict",
        lambda: echelon.Scenario.from_dict,
        dict(document=builtin_document("circle-pentagon"), origin="d", base_dir="."),
        dict(document=[None, "[sim]", ["a"]], origin=TEXT, base_dir=OPTIONAL_PATH),
    ),
    (
        "Scenario.with_overrides",
        lambda: echelon.Scenario.builtin("circle-pentagon").with_overrides,
        dict(dt=0.001, duration=1.0, law="paper", seed=3),
        OVERRIDES,
    ),
    (
        "Scenario.run",
        lambda: echelon.Scenario.builtin("circle-pentagon").run,
        dict(out=None, **SHORT),
        dict(out=OPTIONAL_PATH, **OVERRIDES),
    ),
    ("Run.plot", lambda: echelon.Scenario.builtin("circle-pentagon", **SHORT).run().plot, dict(files=True), dict(files=FLAG)),
    (
        "Run.report",
        lambda: echelon.Scenario.builtin("circle-pentagon", **SHORT).run().report,
        dict(path="report.html"),
        dict(path=PATH),
    ),
    (
        "Simulation",
        lambda: echelon.Simulation,
        dict(scenario="circle-pentagon", safety=False, dt=0.001, duration=1.0, law="paper", seed=3),
        dict(scenario=SCENARIO, safety=FLAG, **OVERRIDES),
    ),
    (
        "Simulation.leader",
        lambda: simulation().leader,
        dict(i=1, commands=np.zeros((4, 2))),
        dict(i=INT, commands=OPTIONAL_ARRAY),
    ),
    (
        "Simulation.step",
        lambda: simulation().step,
        dict(commands=np.zeros((4, 2)), filter=True),
        dict(commands=ARRAY, filter=OPTIONAL_FLAG),
    ),
    (
        "Simulation.step_by",
        lambda: simulation().step_by,
        dict(law=lambda i, t, s, leader: (0.0, 0.0)),
        dict(law=[None, "abc", 1]),
    ),
    (
        "bound",
        lambda: echelon.bound,
        dict(ke=1.0, zeta=1e-5, kz=10.0, omega_max=1.0, gamma=0.99, steps=10, ts=0.01, law="paper"),
        dict(
            ke=FINITE, zeta=FINITE, kz=OPTIONAL_FINITE, omega_max=OPTIONAL_FINITE, gamma=FINITE,
            steps=OPTIONAL_INT, max_z=["1", ["a"]], ts=OPTIONAL_FINITE, law=TEXT,
        ),
    ),
    (
        "law.paper",
        lambda: echelon.law.paper,
        dict(state=[0.0, 0.0, 0.0, 0.1, 0.0], leader=LEADER, robot="agent1", ke=1.5, kz=10.0, variant="complete"),
        dict(state=ARRAY, leader=[None, "abc", ["a"]], robot=[None, 1, ["a"]], ke=FINITE, kz=FINITE, variant=TEXT),
    ),
    (
        "law.kinematic",
        lambda: echelon.law.kinematic,
        dict(state=[0.0, 0.0, 0.0], leader=LEADER, ke=1.5),
        dict(state=ARRAY, leader=[None, "abc", ["a"]], ke=FINITE),
    ),
    ("law.commands", lambda: echelon.law.commands, dict(sim=simulation()), dict(sim=[None, "abc"])),
    ("law.own", lambda: echelon.law.own, dict(sim=simulation()), dict(sim=[None, "abc"])),
    (
        "safety.Filter",
        lambda: echelon.safety.Filter,
        dict(n=2, radius=0.3, gain=1.0, range=2.0, l=0.1, obstacles=OBSTACLES, period=0.01, base="jackal"),
        dict(
            n=INT, radius=FINITE, gain=FINITE, range=NUMBER + [NAN], l=FINITE, obstacles=OPTIONAL_ARRAY,
            period=FINITE, base=TEXT,
        ),
    ),
    (
        "safety.Filter()",
        lambda: echelon.safety.Filter(2, 0.3),
        dict(poses=POSES, commands=COMMANDS, t=0.5),
        dict(poses=ARRAY, commands=ARRAY, t=FINITE),
    ),
    (
        "safety.filter",
        lambda: echelon.safety.filter,
        dict(poses=POSES, commands=COMMANDS, radius=0.3, obstacles=OBSTACLES, gain=1.0, range=2.0, l=0.1),
        dict(poses=ARRAY, commands=ARRAY, radius=FINITE, obstacles=OPTIONAL_ARRAY, gain=FINITE, l=FINITE),
    ),
    (
        "safety.TorqueFilter",
        lambda: echelon.safety.TorqueFilter,
        dict(n=2, radius=0.3, robot=["agent1", "agent2"], gain=1.0, range=2.0, l=0.1, obstacles=OBSTACLES),
        dict(
            n=INT, radius=FINITE, robot=[None, 1, ["a"], [None, "agent1"]], gain=FINITE, range=NUMBER + [NAN],
            l=FINITE, obstacles=OPTIONAL_ARRAY,
        ),
    ),
    (
        "safety.TorqueFilter()",
        lambda: echelon.safety.TorqueFilter(2, 0.3),
        dict(states=STATES, commands=COMMANDS, t=0.5),
        dict(states=ARRAY, commands=ARRAY, t=FINITE),
    ),
    (
        "safety.torque_filter",
        lambda: echelon.safety.torque_filter,
        dict(states=STATES, commands=COMMANDS, radius=0.3, robot="agent2", obstacles=OBSTACLES, l=0.1),
        dict(states=ARRAY, commands=ARRAY, radius=FINITE, robot=[None, 1], obstacles=OPTIONAL_ARRAY, l=FINITE),
    ),
    ("safety.points", lambda: echelon.safety.points, dict(poses=POSES, l=0.1), dict(poses=ARRAY, l=FINITE)),
    (
        "sweep",
        lambda: echelon.sweep,
        dict(
            scenario=echelon.Scenario.builtin("circle-pentagon", **SHORT), grid={"fix_every": [5]}, seeds=1,
            first_seed=2, gamma=0.9, transient=0.01, threads=1,
        ),
        dict(
            scenario=SCENARIO, grid=["abc", 1, ["a"]], seeds=["a", None, [1.5]], first_seed=INT, gamma=FINITE,
            transient=OPTIONAL_FINITE, threads=OPTIONAL_INT, executor=[1, ["a"]],
        ),
    ),
    (
        "Sweep.write",
        lambda: echelon.Sweep(echelon._echelon.SWEEP_HEADER + "\n").write,
        dict(path="sweep.csv"),
        dict(path=PATH),
    ),
    (
        "identify",
        lambda: echelon.identify,
        dict(log="no-such-dir", agent=1, model="torque", name="x"),
        dict(log=[None, 1, ["a"]], agent=INT, model=[1, ["a"]], name=TEXT),
    ),
]

#: Calls whose good arguments do not complete here (identify needs a log):
#: their wrong arguments are refused before the log is read.
NOT_COMPLETED = {"identify"}


def _bad_value(bad: Any, good: Any) -> Any:
    if bad is NAN_ARRAY:
        return np.full(np.shape(good), NAN)
    if isinstance(bad, str) and bad in ("float32", "transposed", "read-only"):
        a = np.array(good, dtype=np.float64)
        if bad == "float32":
            return a.astype(np.float32)
        if bad == "transposed":
            return np.asfortranarray(a)
        a.flags.writeable = False
        return a
    return bad


def bad_id(bad: Any) -> str:
    if bad is NAN_ARRAY:
        return "nan-array"
    return re.sub(r"\W+", "_", repr(bad))[:20]


CASES = [
    pytest.param(what, make, good, arg, bad, id=f"{what}-{arg}-{bad_id(bad)}")
    for what, make, good, bads in API
    for arg, values in bads.items()
    for bad in values
]


@pytest.mark.parametrize("what, make, good", [pytest.param(*a[:3], id=a[0]) for a in API])
def test_the_good_arguments_go_through(what, make, good, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if what in NOT_COMPLETED:
        pytest.skip("needs a log")
    make()(**good)


@pytest.mark.parametrize("what, make, good, arg, bad", CASES)
def test_a_wrong_argument_is_refused_naming_it(what, make, good, arg, bad, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    call = make()
    args = dict(good)
    args[arg] = _bad_value(bad, good.get(arg))
    with pytest.raises((TypeError, ValueError)) as info:
        call(**args)
    message = str(info.value)
    # pyo3's own refusal of a type names it as "argument 'x': ...".
    assert re.match(rf"(argument ')?{re.escape(arg)}\b", message), message
    # Numbers in messages are short: no run of 20 digits.
    assert not re.search(r"\d{20}", message), message


def test_the_api_table_covers_every_public_callable():
    # A public function or method added without a row here fails this.
    covered = {what.rstrip("()") for what, *_ in API}
    public = set()
    for name in echelon.__all__:
        obj = getattr(echelon, name)
        if name in ("law", "safety"):
            for sub in obj.__dict__:
                f = getattr(obj, sub)
                if not sub.startswith("_") and callable(f) and getattr(f, "__module__", "") == obj.__name__:
                    public.add(f"{name}.{sub}")
        elif isinstance(obj, type) and not issubclass(obj, Exception):
            public.add(name)
            for sub, f in vars(obj).items():
                if not sub.startswith("_") and (callable(f) or isinstance(f, (classmethod, staticmethod))):
                    public.add(f"{name}.{sub}")
        elif callable(obj) and not isinstance(obj, type):
            public.add(name)
    # Taking no arguments: nothing to get wrong; Run, Sweep and BatchEngine
    # are made by the package (their constructors are not the API).
    no_arguments = {"builtins", "BatchEngine.state", "BatchEngine.buffer", "Simulation.errors"}
    made = {"Run", "Sweep", "BatchEngine", "Scenario"}
    missing = public - covered - no_arguments - made
    assert not missing, sorted(missing)
    assert "safety.points" in public and "Simulation.step" in public  # the walk finds them


@settings(max_examples=60, deadline=None)
@given(dt=st.floats(min_value=1e-300, max_value=1e-4))
def test_a_refused_step_is_written_short_and_exactly(dt):
    # `Simulation(dt=1e-300)` printed a 300-digit dt. A step far too short
    # for the run (too many steps) or one the logging period is no whole
    # multiple of is refused, the step written in a form that reads back to
    # the same float and is short.
    try:
        echelon.Simulation("circle-pentagon", dt=dt)
    except echelon.ScenarioError as e:
        message = str(e)
    else:
        ratio = 0.01 / dt  # log.dt = 0.01 is a whole multiple of dt: fine
        assert abs(ratio - round(ratio)) <= 1e-6 * ratio
        return
    tokens = re.findall(r"\d[\d.]*(?:e-?\d+)?", message)
    assert max(len(t) for t in tokens) <= 24, message
    assert dt in [float(t) for t in tokens], message


def _extension_calls() -> list[tuple[str, Callable[..., Any], dict[str, Any], bool]]:
    """Every array argument of the extension module, with good arguments
    for its call and whether the call writes into it."""
    ext = echelon._echelon
    sim = echelon.Simulation("circle-pentagon")._sim
    filters = ext.SafetyFilters(2, 0.3)
    torque = ext.TorqueSafetyFilters(2, 0.3, [ext.robot_preset("agent1")])
    engine = ext.BatchEngine.bench(3)
    state5, p2, off = np.zeros(5), np.array([0.3, 0.0]), np.array([0.3, 0.0, 0.0, 0.0])
    law = dict(state=state5, p=p2, dp=p2, ddp=p2, offset=off, robot_json=ext.robot_preset("agent1"), ke=1.0, kz=1.0)
    return [
        ("state", engine.step, dict(state=engine.state(), steps=1), True),
        ("out", engine.run, dict(steps=1, out=np.zeros((3, 5))), True),
        ("out", engine.states, dict(out=np.zeros((3, 5))), True),
        *[(k, ext.law_paper, law, False) for k in ("state", "p", "dp", "ddp", "offset")],
        *[
            (k, ext.law_kinematic, dict(state=state5, p=p2, dp=p2, offset=off, ke=1.0), False)
            for k in ("state", "p", "dp", "offset")
        ],
        ("commands", sim.step, dict(commands=np.zeros((4, 2)), filter=False), False),
        ("commands", sim.leader, dict(i=1, commands=np.zeros((4, 2))), False),
        ("obstacles", ext.SafetyFilters, dict(n=2, radius=0.3, obstacles=OBSTACLES.repeat(2, axis=0)), False),
        *[(k, filters.filter, dict(t=0.0, poses=POSES, commands=COMMANDS), False) for k in ("poses", "commands")],
        *[(k, torque.filter, dict(t=0.0, states=STATES, commands=COMMANDS), False) for k in ("states", "commands")],
    ]


@pytest.mark.parametrize("wrong", ["float32", "int64", "fortran", "strided", "shape", "list", "read-only"])
@pytest.mark.parametrize("index", range(len(_extension_calls())))
def test_every_array_argument_of_the_extension_is_checked_alike(index, wrong):
    name, call, good, writes = _extension_calls()[index]
    call(**good)  # the good arguments go through
    good = dict(_extension_calls()[index][2])
    a = np.array(good[name], dtype=np.float64)
    if (wrong == "read-only" and not writes) or (wrong == "fortran" and a.ndim == 1):
        pytest.skip("read only, a read-only array is fine; 1-D has no Fortran order")
    bad = {
        "float32": lambda: a.astype(np.float32),
        "int64": lambda: a.astype(np.int64),
        "fortran": lambda: np.asfortranarray(a),
        "strided": lambda: np.repeat(a, 2, axis=-1)[..., ::2],
        "shape": lambda: np.zeros(a.shape + (1,)),
        "list": lambda: a.tolist(),
        "read-only": lambda: np.frombuffer(a.tobytes(), dtype=np.float64).reshape(a.shape),
    }[wrong]()
    good[name] = bad
    with pytest.raises(ValueError) as info:
        _extension_calls()[index][1](**good)
    message = str(info.value)
    layout = "C-contiguous and writeable" if writes else "C-contiguous"
    assert re.match(rf"{name} must be a float64 array of shape \(.*\), {layout}, got ", message), message
