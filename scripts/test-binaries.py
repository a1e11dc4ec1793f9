#!/usr/bin/env python3
"""Runs the workspace's built test binaries, one lane of them, one at a time.

`scripts/test` builds every test once (`cargo test --no-run
--message-format=json`) and then runs two lanes side by side:

- `fleet`: the echelon-cli tests that start fleets (processes talking over
  Zenoh, timing-bound, mostly waiting: about 12 of the 16 minutes of Rust
  tests on two cores). They run one fleet at a time machine-wide anyway
  (`one_fleet_at_a_time`, a lock file), so a fleet test in the other lane
  would wait for its turn, never run beside another fleet.
- `rest`: every other test binary (CPU-bound), which `scripts/test` runs at a
  lower priority so the fleets keep the CPU they need and the rest take what
  they leave idle.

Each binary runs as `cargo test` runs it: from its package's directory, with
`CARGO_MANIFEST_DIR` and `CARGO_PKG_NAME` set; extra arguments go to every
binary (e.g. `--nocapture`). Every binary runs even when one fails (like
`cargo test --no-fail-fast`); the exit status is 1 if any failed, and the
failures are listed at the end.

Usage: test-binaries.py --lane {fleet,rest} ARTIFACTS.json [-- ARGS...]
"""

import argparse
import json
import os
import signal
import subprocess
import sys
import time

# The echelon-cli integration tests that start fleets (crates/echelon-cli/tests).
FLEET_TESTS = {"fleet", "fleet_fixes", "fleet_head", "fleet_ros2", "fleet_stop", "foxglove"}


def package_name(package_id):
    """The name in a package id: `path+file:///…/echelon-cli#0.1.0` (the
    directory's name) or `path+file:///…/python#echelon-py@0.1.0`."""
    path, _, fragment = package_id.partition("#")
    if "@" in fragment:
        return fragment.split("@")[0]
    return path.rstrip("/").rsplit("/", 1)[-1]


def test_binaries(artifacts_path):
    """(package, target kind, target name, source, executable, manifest dir) of
    every test binary `cargo test --no-run --message-format=json` built."""
    binaries = []
    with open(artifacts_path, encoding="utf-8") as f:
        for line in f:
            line = line.strip()
            if not line.startswith("{"):
                continue
            msg = json.loads(line)
            if msg.get("reason") != "compiler-artifact" or not msg.get("executable"):
                continue
            if not msg.get("profile", {}).get("test"):
                continue
            target = msg["target"]
            manifest_dir = os.path.dirname(msg["manifest_path"])
            package = package_name(msg["package_id"])
            kind = "unittests" if "test" not in target["kind"] else "tests"
            source = os.path.relpath(target["src_path"], manifest_dir)
            binaries.append((package, kind, target["name"], source, msg["executable"], manifest_dir))
    return binaries


def in_lane(binary, lane):
    package, kind, name = binary[0], binary[1], binary[2]
    is_fleet = package == "echelon-cli" and kind == "tests" and name in FLEET_TESTS
    return is_fleet == (lane == "fleet")


def main():
    argv = sys.argv[1:]
    extra = []
    if "--" in argv:
        cut = argv.index("--")
        argv, extra = argv[:cut], argv[cut + 1 :]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lane", choices=["fleet", "rest"], required=True)
    parser.add_argument("artifacts")
    args = parser.parse_args(argv)

    # A background job of a non-interactive shell starts with SIGINT ignored,
    # and its children would inherit that: tests that stop a fleet (or a
    # Python peer) with SIGINT need the default.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    binaries = sorted(b for b in test_binaries(args.artifacts) if in_lane(b, args.lane))
    if not binaries:
        print(f"no test binaries in lane {args.lane} ({args.artifacts})", file=sys.stderr)
        return 1
    failed = []
    start = time.monotonic()
    for package, kind, name, source, exe, manifest_dir in binaries:
        print(f"     Running {package} {source} ({os.path.relpath(exe)})", flush=True)
        env = dict(os.environ, CARGO_MANIFEST_DIR=manifest_dir, CARGO_PKG_NAME=package)
        t0 = time.monotonic()
        rc = subprocess.call([exe, *extra], cwd=manifest_dir, env=env)
        if rc != 0:
            failed.append(f"{package} {source} (exit {rc}, {time.monotonic() - t0:.0f} s)")
    took = time.monotonic() - start
    print(f"== lane {args.lane}: {len(binaries)} test binaries in {took:.0f} s, {len(failed)} failed", flush=True)
    for f in failed:
        print(f"   FAILED: {f}", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
