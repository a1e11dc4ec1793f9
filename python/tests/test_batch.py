"""The batch engine stepping state in arrays the caller owns (issue 24, item 3):
`BatchEngine.state()` hands out a `(5, n)` array, `BatchEngine.step(state,
steps)` steps it in place with the GIL released."""

from __future__ import annotations

import _thread
import signal
import threading
import time

import numpy as np
import pytest

import echelon
from conftest import counts_while

CASES = [
    (topology, drive, n)
    for topology in ("star", "chain")
    for drive in ("torque", "velocity")
    # A partial last block (8 lanes per block), several parallel tasks, and a
    # chain long enough to run as two halves on two threads.
    for n in (1, 13, 77, 600)
]


@pytest.mark.parametrize("topology, drive, n", CASES)
def test_step_changes_the_callers_array_in_place_and_equals_run(topology, drive, n):
    seed = 11 + n
    e = echelon.BatchEngine.bench(n, topology=topology, drive=drive, dt=0.001, seed=seed)
    state = e.state()
    assert state.shape == (5, n) and state.dtype == np.float64 and state.flags.c_contiguous
    start = state.copy()
    # The engine's own rows (n, 5) are the columns' transpose.
    own = np.empty((n, 5))
    e.states(own)
    np.testing.assert_array_equal(state, own.T)
    assert np.all(start[3:] == 0.0)  # at rest

    pointer = state.__array_interface__["data"][0]
    # Uneven calls: within a tile, across tile boundaries, one step.
    for steps in (1, 63, 2, 130, 4):
        assert e.step(state, steps) is state
    assert state.__array_interface__["data"][0] == pointer
    assert e.time == pytest.approx(0.2)
    assert np.all(np.isfinite(state)) and not np.array_equal(state, start)

    # The same formation run by the engine on its own state: the same bits.
    ref = echelon.BatchEngine.bench(n, topology=topology, drive=drive, dt=0.001, seed=seed)
    out = np.empty((n, 5))
    ref.run(200, out=out)
    np.testing.assert_array_equal(state, out.T)
    # and the engine's own states follow the caller's buffer.
    e.states(own)
    np.testing.assert_array_equal(own.T, state)


def test_the_callers_state_is_what_is_stepped():
    # Move one robot in the caller's array: the engine steps the moved robot
    # from there, as a fresh engine started at that state would.
    e = echelon.BatchEngine.bench(16, seed=4)
    state = e.state()
    e.step(state, 10)
    state[0, 5] += 0.5  # x of agent 6
    state[2, 5] -= 0.25  # its heading
    moved = state.copy()
    e.step(state, 50)
    assert not np.array_equal(state[:, 5], moved[:, 5])
    # The others did not feel it (a star): they are where an untouched run puts them.
    other = echelon.BatchEngine.bench(16, seed=4)
    s2 = other.state()
    other.step(s2, 60)
    keep = [i for i in range(16) if i != 5]
    np.testing.assert_array_equal(state[:, keep], s2[:, keep])
    assert not np.array_equal(state[:, 5], s2[:, 5])


BAD = {
    "wrong shape": lambda n: np.zeros((n, 5)),
    "too few agents": lambda n: np.zeros((5, n - 1)),
    "one dimension": lambda n: np.zeros(5 * n),
    "float32": lambda n: np.zeros((5, n), dtype=np.float32),
    "int64": lambda n: np.zeros((5, n), dtype=np.int64),
    "Fortran order": lambda n: np.asfortranarray(np.zeros((5, n))),
    "strided view": lambda n: np.zeros((5, 2 * n))[:, ::2],
    "a list": lambda n: [[0.0] * n for _ in range(5)],
}


@pytest.mark.parametrize("what", sorted(BAD))
def test_a_wrong_array_raises_valueerror_and_changes_nothing(what):
    e = echelon.BatchEngine.bench(9, seed=2)
    good = e.state()
    e.step(good, 5)
    before, t = good.copy(), e.time
    bad = BAD[what](9)
    snapshot = np.array(bad, copy=True)
    with pytest.raises(ValueError, match="state"):
        e.step(bad, 3)
    np.testing.assert_array_equal(np.asarray(bad), snapshot)
    assert e.time == t
    # The engine is untouched: it goes on from where it was.
    e.step(good, 7)
    ref = echelon.BatchEngine.bench(9, seed=2)
    s = ref.state()
    ref.step(s, 12)
    np.testing.assert_array_equal(good, s)
    assert not np.array_equal(good, before)


def test_a_read_only_or_non_finite_array_raises_valueerror_and_changes_nothing():
    e = echelon.BatchEngine.bench(9, seed=2)
    state = e.state()
    state.flags.writeable = False
    with pytest.raises(ValueError, match="writeable"):
        e.step(state, 1)
    state = e.state()
    state[3, 4] = np.nan
    snapshot = state.copy()
    with pytest.raises(ValueError, match="v of agent 5"):
        e.step(state, 1)
    np.testing.assert_array_equal(state, snapshot)
    assert e.time == 0.0
    state[3, 4] = 0.0
    e.step(state, 1)
    assert e.time == pytest.approx(0.001)


def test_step_releases_the_gil():
    e = echelon.BatchEngine.bench(20_000, dt=0.001)
    state = e.state()
    during = counts_while(lambda: e.step(state, 400))
    assert during > 10_000, during


@pytest.mark.parametrize("drive", ["torque", "velocity"])
@pytest.mark.parametrize("dt", [float("nan"), float("inf"), -1e-3, 0.0, -0.0])
def test_a_bench_with_an_impossible_step_names_dt(drive, dt):
    with pytest.raises(ValueError, match=r"^dt: .* must be a finite number > 0"):
        echelon.BatchEngine.bench(3, drive=drive, dt=dt)


@pytest.mark.parametrize("dt", [0.0500001, 0.3, 7.5])
def test_a_velocity_bench_step_past_the_lag_names_dt_and_the_limit(dt):
    with pytest.raises(ValueError, match=rf"^dt: {dt} s is longer than .* lag .* use dt ≤ 0.05"):
        echelon.BatchEngine.bench(3, drive="velocity", dt=dt)


@pytest.mark.parametrize("agents", [100_000_001, 2**40, 2**63])
def test_a_bench_past_memory_is_a_valueerror_not_an_abort(agents):
    # It used to abort the interpreter ("memory allocation of … failed").
    with pytest.raises(ValueError, match=f"^agents: {agents} is more than 100000000"):
        echelon.BatchEngine.bench(agents)


@pytest.mark.parametrize("topology, drive", [(t, d) for t in ("star", "chain") for d in ("torque", "velocity")])
def test_a_call_stepped_in_chunks_is_the_same_bits_as_one_step_at_a_time(topology, drive):
    # 600 agents: 436 steps per chunk, so 1000 steps are three chunks
    # (436, 436, 128) in one call; against 1000 calls of one step each.
    n, steps = 600, 1000
    whole = echelon.BatchEngine.bench(n, topology=topology, drive=drive, seed=8)
    state = whole.state()
    whole.step(state, steps)
    single = echelon.BatchEngine.bench(n, topology=topology, drive=drive, seed=8)
    one = single.state()
    for _ in range(steps):
        single.step(one, 1)
    np.testing.assert_array_equal(state, one)
    assert whole.time == single.time
    # run() is chunked the same way.
    kept = echelon.BatchEngine.bench(n, topology=topology, drive=drive, seed=8)
    out = kept.buffer()
    kept.run(steps, out=out)
    np.testing.assert_array_equal(out.T, one)


def _interrupt_inside(engine: echelon.BatchEngine, stop: threading.Event) -> threading.Thread:
    """A thread that waits until ``engine`` is inside a call that holds it
    (reading its time is then refused: it is borrowed), then interrupts the
    main thread as Ctrl-C does: no clock decides when."""

    def watch() -> None:
        while not stop.is_set():
            try:
                engine._inner.time
            except RuntimeError:  # already mutably borrowed: inside the call
                _thread.interrupt_main()
                return
            time.sleep(0.0005)

    t = threading.Thread(target=watch, daemon=True)
    t.start()
    return t


@pytest.mark.parametrize("method", ["step", "run"])
@pytest.mark.parametrize("drive", ["torque", "velocity"])
def test_ctrl_c_interrupts_a_long_call_which_keeps_its_finished_chunks(method, drive):
    # 64 agents: 4096 steps per chunk; the call asks for 300 chunks, far
    # more than the interrupt lets it finish (a call that ignored signals
    # would run them all, then fail the `k < total` below).
    n, total, dt = 64, 300 * 4096, 0.001
    e = echelon.BatchEngine.bench(n, drive=drive, dt=dt, seed=3)
    state = e.state()
    stop = threading.Event()
    # Ctrl-C as Python handles it, whatever this process inherited: a
    # process started in the background by a non-interactive shell (`cmd &`,
    # nohup, some CI runners) starts with SIGINT ignored, Python then leaves
    # it ignored, and `interrupt_main` does nothing — the test failed so
    # (all four cases: "DID NOT RAISE KeyboardInterrupt") on a first run
    # started that way.
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    watcher = _interrupt_inside(e, stop)
    try:
        with pytest.raises(KeyboardInterrupt):
            if method == "step":
                e.step(state, total)
            else:
                e.run(total)
    finally:
        stop.set()
        watcher.join()
        signal.signal(signal.SIGINT, inherited)
    k = round(e.time / dt)
    assert 0 < k < total and k % 4096 == 0, k
    # The states are those of k steps: as a fresh engine steps them.
    ref = echelon.BatchEngine.bench(n, drive=drive, dt=dt, seed=3)
    expected = ref.state()
    ref.step(expected, k)
    if method == "run":
        state = e.buffer()
        e.states(state)
        state = state.T
    np.testing.assert_array_equal(state, expected)
    # And the engine goes on from there.
    e.run(5)
    ref.run(5)
    np.testing.assert_array_equal(e.states(e.buffer()), ref.states(ref.buffer()))
