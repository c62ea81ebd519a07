#!/usr/bin/env bash
# The stress suite (issue 8), one command:
#   scripts/stress.sh          fast part (what CI runs, about 1 minute): the hostile-input,
#                              geometry, repeatability, scale and format tests, then 20 s of
#                              fuzzing of each reader (`prt-bench fuzz`)
#   scripts/stress.sh --long   on demand: the same tests, then 5 minutes of fuzzing per reader
#                              and seed (three seeds), failing inputs saved to target/fuzz-failures
# Fuzzing runs under a 6 GB address-space limit, so that an allocation bomb aborts the run (a
# failure) instead of taking the machine down.
set -euo pipefail
cd "$(dirname "$0")/.."
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"
seconds=20
seeds="1"
if [[ "${1:-}" == "--long" ]]; then
    seconds=300
    seeds="1 2 3"
fi
cargo test --release -p prt-tests --test hostile --test geometry --test repeat --test scale --test sums --test format
cargo build --release -p prt-bench
target_dir="${CARGO_TARGET_DIR:-target}"
bench="$target_dir/release/prt-bench"
out="$target_dir/fuzz-failures"
mkdir -p "$out"
for seed in $seeds; do
    for target in gltf asset; do
        # A hang inside one input is only noticed when it returns: bound the whole run.
        (ulimit -v 6000000; timeout $((seconds + 120)) "$bench" fuzz --target "$target" --seconds "$seconds" --seed "$seed" --out "$out")
    done
done
