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
cargo clippy --release --all-targets -- -D warnings
cargo test --release --workspace
