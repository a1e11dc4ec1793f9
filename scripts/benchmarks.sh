#!/usr/bin/env bash
# Reproduces the tables of BENCHMARKS.md: each configuration of `echelon bench`
# REPEAT times (default 3), the median agent-steps per second. Needs a release
# build: cargo build --release. Other processes on the machine lower the
# figures; `uptime` is printed before and after.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/echelon
repeat=${REPEAT:-3}

median() { sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }

run() {
    local label=$1; shift
    local rates=()
    for _ in $(seq "$repeat"); do
        rates+=("$("$bin" bench "$@" --json | sed -E 's/.*"agent_steps_per_s":([0-9.e+]+).*/\1/')")
    done
    local m
    m=$(printf '%s\n' "${rates[@]}" | median)
    printf '%-44s %8.1f M agent-steps/s  (%s)\n' "$label" "$(awk "BEGIN {print $m / 1e6}")" \
        "$(printf '%s\n' "${rates[@]}" | awk '{printf "%.1f ", $1 / 1e6}')"
}

uptime
for n in 1000 10000 100000 1000000; do
    steps=$((100000000 / n)); [ "$steps" -gt 10000 ] && steps=10000
    duration=$(awk "BEGIN {print $steps * 0.001}")
    for k in 1 2; do
        run "star N=$n, $k thread(s)" --agents "$n" --duration "$duration" --dt 0.001 --threads "$k"
    done
done
run "chain N=10000, 1 thread" --agents 10000 --topology chain --duration 5 --dt 0.001 --threads 1
run "chain N=10000, 2 threads (two halves)" --agents 10000 --topology chain --duration 5 --dt 0.001 --threads 2
run "chain N=10000 x 2 runs, 2 threads" --agents 10000 --runs 2 --topology chain --duration 5 --dt 0.001 --threads 2
run "sweep: 256 runs of N=4, 2 threads" --agents 4 --runs 256 --duration 10 --dt 0.001 --threads 2
for k in 1 2; do
    run "velocity star N=10000, $k thread(s)" --drive velocity --agents 10000 --duration 10 --dt 0.001 --threads "$k"
done
run "velocity chain N=10000, 1 thread" --drive velocity --agents 10000 --topology chain --duration 5 --dt 0.001 --threads 1
uptime
