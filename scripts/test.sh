#!/usr/bin/env bash
# The whole test suite (what CI runs): formatting, lints, then every test in release mode.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all -- --check
cargo clippy --release --all-targets -- -D warnings
cargo test --release --workspace
