#!/usr/bin/env python3
"""`echelon bench` (star, torque) against its Numba peer, side by side.

Checks first that the peer computes what echelon computes (a short run:
every agent's final state against the batch engine's through the `echelon`
Python package when it is installed, and the largest ‖e‖ against
`echelon bench --json` always), then times `--pairs` pairs, each
`echelon bench` (a release build, its own process) followed by the peer on
the same workload, and prints both medians, their ratio and the machine.

The peer is `numba_star` (tiled, vectorised: the strongest we have);
`--peers numba_star,numba_star_plain` also times the plain version (libm,
one agent at a time) in the same pairs.

    python3 -m venv --system-site-packages .venv-peers
    .venv-peers/bin/pip install -r benches/peers/requirements.txt
    cargo build --release -p echelon-cli
    .venv-peers/bin/python benches/peers/run.py --pairs 5

Agent-steps per second count `N × steps / wall seconds` of the stepping
alone on both sides (echelon excludes building the formation; the peer
excludes building it and compiling, and includes evaluating the reference).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]


def machine() -> str:
    model, cores = platform.processor() or "?", os.cpu_count()
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        fields = dict(line.split(":", 1) for line in out.splitlines() if ":" in line)
        model = fields.get("Model name", model).strip()
        flags = fields.get("Flags", "")
        simd = [f for f in ("avx2", "fma", "avx512f") if f in flags.split()]
        cores = f"{fields.get('CPU(s)', cores).strip()} CPUs, {simd}"
    except (OSError, subprocess.CalledProcessError):
        pass
    return f"{model}, {cores}"


def echelon_bin(given: str | None) -> Path:
    if given:
        return Path(given)
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    return target / "release" / "echelon"


def echelon_bench(exe: Path, agents: int, duration: float, dt: float, threads: int) -> dict:
    cmd = [str(exe), "bench", "--agents", str(agents), "--topology", "star", "--drive", "torque",
           "--duration", repr(duration), "--dt", repr(dt), "--threads", str(threads), "--json"]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    return json.loads(out)


def check(peer, exe: Path, threads: int) -> None:
    """The peer's states equal the batch engine's: 1 000 agents, 0.5 s."""
    agents, steps, dt = 1000, 500, 0.001
    star = peer.Star(agents, dt)
    star.run(steps)
    rel = lambda a, b: abs(a - b) / max(abs(a), abs(b), 1.0)  # noqa: E731
    cli = echelon_bench(exe, agents, steps * dt, dt, threads)
    mine = float(star.errors().max())
    worst = rel(mine, cli["max_error"])
    print(f"check, {agents} agents, {steps} steps: max ‖e‖ {mine:.12e} m (peer) vs "
          f"{cli['max_error']:.12e} m (echelon bench): relative difference {worst:.1e}")
    if worst > 1e-9:
        sys.exit("the peer does not compute what echelon computes (max ‖e‖)")
    try:
        import echelon  # noqa: PLC0415
    except ImportError:
        print("check: the echelon Python package is not installed; states not compared one by one")
        return
    import numpy as np  # noqa: PLC0415

    e = echelon.BatchEngine.bench(agents, topology="star", drive="torque", dt=dt, seed=1)
    state = e.state()
    e.step(state, steps)
    mine = star.states().T
    scale = np.maximum(np.maximum(abs(state), abs(mine)), 1.0)
    worst = float(np.max(abs(state - mine) / scale))
    print(f"check: every agent's x, y, θ, v, ω after {steps} steps, peer vs the batch engine: "
          f"largest relative difference {worst:.1e}")
    if worst > 1e-9:
        sys.exit("the peer does not compute what echelon computes (states)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--agents", type=int, default=10_000)
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--dt", type=float, default=0.001)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--pairs", type=int, default=5)
    p.add_argument("--echelon", help="the echelon binary [default: $CARGO_TARGET_DIR or target, release]")
    p.add_argument("--peers", default="numba_star",
                   help="comma-separated peer modules in benches/peers, each timed in every pair [default: numba_star]")
    a = p.parse_args()

    os.environ["NUMBA_NUM_THREADS"] = str(a.threads)
    sys.path.insert(0, str(HERE))
    import numba  # noqa: PLC0415

    names = [n.strip() for n in a.peers.split(",") if n.strip()]
    # numba_star first: it sets Numba's CPU features before anything compiles.
    peers = {n: importlib.import_module(n) for n in sorted(names, key=lambda n: n != "numba_star")}

    exe = echelon_bin(a.echelon)
    steps = max(1, round(a.duration / a.dt))
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for name in names:
        # Compile the peer (not timed), then check it.
        peers[name].Star(16, a.dt).run(2)
        print(f"{name}:")
        check(peers[name], exe, a.threads)
    from numba.core.registry import cpu_target  # noqa: PLC0415

    # What the compiler was given (numba_star asks for 512-bit vectors unless
    # NUMBA_CPU_FEATURES says otherwise).
    wide = "-prefer-256-bit" in cpu_target.target_context.codegen()._tm_features.split(",")
    vectors = "512-bit vectors preferred" if wide else "LLVM's default vector width"
    print(f"machine: {machine()}; numba {numba.__version__} on {numba.get_num_threads()} threads "
          f"({numba.threading_layer()}), {vectors}")

    ours, theirs = [], {n: [] for n in names}
    for i in range(a.pairs):
        r = echelon_bench(exe, a.agents, a.duration, a.dt, a.threads)
        ours.append(r["agent_steps_per_s"])
        line = f"pair {i + 1}: echelon {ours[-1] / 1e6:.1f}"
        for name in names:
            star = peers[name].Star(a.agents, a.dt)
            t0 = time.perf_counter()
            star.run(steps)
            theirs[name].append(a.agents * steps / (time.perf_counter() - t0))
            line += f", {name} {theirs[name][-1] / 1e6:.1f}"
        print(line + " M agent-steps/s")
    mo = statistics.median(ours)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"star, torque, N = {a.agents}, {steps} steps of {a.dt} s, {a.threads} threads, "
          f"median of {a.pairs} interleaved pairs:")
    print(f"  echelon bench: {mo / 1e6:.1f} M agent-steps/s ({1e9 / mo:.2f} ns per agent-step)")
    for name in names:
        mt = statistics.median(theirs[name])
        print(f"  {name + ':':17s}{mt / 1e6:.1f} M agent-steps/s ({1e9 / mt:.2f} ns per agent-step), "
              f"ratio {mo / mt:.2f}x")


if __name__ == "__main__":
    main()
