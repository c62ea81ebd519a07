#!/usr/bin/env bash
# Installs the system packages prt's tests need on a fresh Debian machine (idempotent).
set -euo pipefail
need=()
command -v cargo >/dev/null || { echo "setup: cargo not found; install Rust (rustup) first" >&2; exit 1; }
if [ ${#need[@]} -gt 0 ]; then
  apt-get update -qq && apt-get install -y -qq "${need[@]}"
fi
