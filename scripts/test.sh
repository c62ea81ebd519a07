#!/usr/bin/env bash
# The whole test suite (what CI runs): installs the Vulkan driver if missing, checks formatting
# and lints, then runs every test in release mode (GPU tests run on lavapipe without a GPU and
# fail, never skip, when no adapter is found).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
# Mesa prints a warning for every device when this is unset.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"
cargo fmt --all -- --check
# No two modules of a crate import each other, directly or round a circle (issue 30).
for crate in format shaders scene bake runtime render eval cli bench tests; do
    python3 scripts/module_graph.py "$crate/src" --nested >/dev/null || { python3 scripts/module_graph.py "$crate/src" --nested | tail -5; exit 1; }
done
cargo clippy --release --all-targets -- -D warnings
cargo test --release --workspace
