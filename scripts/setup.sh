#!/usr/bin/env bash
# Installs what prt's tests need on a fresh Debian machine (idempotent): a Vulkan driver, so
# that wgpu finds an adapter. Without a GPU that is Mesa's lavapipe (software Vulkan).
set -euo pipefail
command -v cargo >/dev/null || { echo "setup: cargo not found; install Rust (rustup) first" >&2; exit 1; }
if ! ls /usr/share/vulkan/icd.d/*.json >/dev/null 2>&1; then
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  # Another apt (an unattended upgrade on a fresh machine) may hold the lock for a while: wait
  # for it rather than fail.
  lock="-o DPkg::Lock::Timeout=600"
  for attempt in 1 2 3 4 5 6 7 8 9 10; do
    $sudo apt-get $lock update -qq && break
    echo "setup: apt-get update failed (attempt $attempt); retrying in 30 s" >&2
    sleep 30
  done
  DEBIAN_FRONTEND=noninteractive $sudo apt-get $lock install -y -qq mesa-vulkan-drivers >/dev/null
fi
