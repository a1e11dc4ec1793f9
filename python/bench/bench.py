"""Benchmarks of the Python package (not tests; BENCHMARKS.md, "Python").

1. The batch engine driven from Python against `echelon bench` on the same
   workload (same formation, seed, dt, steps): agent-steps per second.
2. The cost of one `Simulation.step` call for 4 agents (circle-pentagon),
   against the simulator's own step time in `echelon run`.

Run with a release build of the package (`pip install ./python`) and a
release `echelon` binary:

    python3 python/bench/bench.py --echelon target/release/echelon
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time

import numpy as np

import echelon


def batch(agents: int, duration: float, dt: float, topology: str, drive: str, cli: str, repeat: int) -> dict:
    """Median agent-steps/s of `repeat` runs each, Python and CLI alternating
    (so that a load change hits both)."""
    steps = int(np.ceil(duration / dt - 1e-9))
    cmd = [cli, "bench", "--agents", str(agents), "--duration", str(duration), "--dt", str(dt),
           "--topology", topology, "--drive", drive, "--json"]
    py, rust = [], []
    for _ in range(repeat):
        e = echelon.BatchEngine.bench(agents, topology=topology, drive=drive, dt=dt, seed=1)
        out = e.buffer()
        started = time.perf_counter()
        e.run(steps, out=out)
        py.append(agents * steps / (time.perf_counter() - started))
        res = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
        rust.append(res["agent_steps_per_s"])
    py_rate, rust_rate = float(np.median(py)), float(np.median(rust))
    return {"workload": f"{agents} agents, {topology}, {drive}, {steps} steps", "python": py_rate,
            "cli": rust_rate, "ratio": py_rate / rust_rate}


def step_overhead(calls: int) -> dict:
    s = echelon.Scenario.builtin("circle-pentagon")
    sim = echelon.Simulation(s)
    cmd = np.zeros((sim.n, 2))
    for _ in range(100):
        sim.step(cmd)
    started = time.perf_counter()
    for _ in range(calls):
        sim.step(cmd)
    per_call = (time.perf_counter() - started) / calls
    # The extension's method alone (no wrapper, no array conversion).
    inner = sim._sim
    started = time.perf_counter()
    for _ in range(calls):
        inner.step(cmd)
    per_inner = (time.perf_counter() - started) / calls
    # A method call that does nothing: the floor of any call from Python.
    started = time.perf_counter()
    for _ in range(calls):
        inner.step_index
    per_getter = (time.perf_counter() - started) / calls
    # The simulator's own step, law included, in a plain run (logging every 10 steps).
    run_started = time.perf_counter()
    run = s.run(duration=calls * sim.dt)
    per_step_run = (time.perf_counter() - run_started) / run.summary["steps"]
    law_started = time.perf_counter()
    k = 0
    while k < calls // 10:
        echelon.law.commands(sim)
        k += 1
    per_law = (time.perf_counter() - law_started) / max(k, 1)
    return {"step_us": per_call * 1e6, "inner_step_us": per_inner * 1e6, "getter_us": per_getter * 1e6,
            "echelon_run_step_us": per_step_run * 1e6,
            "law_commands_us": per_law * 1e6}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--echelon", default="echelon")
    ap.add_argument("--agents", type=int, default=10_000)
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--dt", type=float, default=0.001)
    ap.add_argument("--calls", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    for topology, drive in [("star", "torque"), ("chain", "torque"), ("star", "velocity")]:
        r = batch(a.agents, a.duration, a.dt, topology, drive, a.echelon, a.repeat)
        print(f"{r['workload']}: python {r['python']:.3e} agent-steps/s, "
              f"echelon bench {r['cli']:.3e}, {100 * r['ratio']:.1f} % (medians of {a.repeat})")
    o = step_overhead(a.calls)
    print(f"Simulation.step, 4 agents: {o['step_us']:.2f} µs/call ({o['inner_step_us']:.2f} µs "
          f"calling the extension directly; an empty getter call {o['getter_us']:.3f} µs); echelon run's step "
          f"(law, logging included): {o['echelon_run_step_us']:.2f} µs; echelon.law.commands "
          f"for 4 agents in Python: {o['law_commands_us']:.1f} µs")


if __name__ == "__main__":
    main()
