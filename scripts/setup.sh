#!/usr/bin/env bash
# Installs what prt's tests need on a fresh Debian machine (idempotent): a Vulkan driver, so
# that wgpu finds an adapter. Without a GPU that is Mesa's lavapipe (software Vulkan).
set -euo pipefail
command -v cargo >/dev/null || { echo "setup: cargo not found; install Rust (rustup) first" >&2; exit 1; }
if ! ls /usr/share/vulkan/icd.d/*.json >/dev/null 2>&1; then
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq mesa-vulkan-drivers >/dev/null
fi
