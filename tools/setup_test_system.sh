#!/usr/bin/env bash
# System packages the tests drive for real: tmux (terminal UI tests), Xvfb and libXtst (PyBullet
# window and keys typed into it), mesa-vulkan-drivers (headless Rerun viewer screenshots), chromium
# (the Rerun web viewer loaded in a real browser, driven by Playwright; its own browser download is not used).
# Installs only what is missing.
set -euo pipefail
need=()
command -v tmux >/dev/null 2>&1 || need+=(tmux)
command -v Xvfb >/dev/null 2>&1 || need+=(xvfb)
dpkg -s mesa-vulkan-drivers >/dev/null 2>&1 || need+=(mesa-vulkan-drivers)
dpkg -s libxtst6 >/dev/null 2>&1 || need+=(libxtst6)  # typing into the PyBullet window under Xvfb
command -v chromium >/dev/null 2>&1 || need+=(chromium)  # tests/cli/test_web_view.py
if [ ${#need[@]} -gt 0 ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "setup_test_system: missing ${need[*]}; run as root or install them: apt-get install ${need[*]}" >&2
    exit 1
  fi
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need[@]}" >/dev/null
fi
