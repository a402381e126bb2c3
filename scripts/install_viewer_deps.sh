#!/usr/bin/env bash
# Debian packages for rendering Rerun recordings headless (mavins/review.py):
# Xvfb (virtual X server), Mesa's software Vulkan driver (lavapipe) with the
# Vulkan loader, and the X11/xkb libraries the viewer (rerun_cli/rerun) loads
# at run time. Idempotent and quiet (prints one line only when it installs
# something); needs root or sudo. CI calls it before the tests.
set -euo pipefail

PACKAGES=(
  xvfb                     # Xvfb
  mesa-vulkan-drivers      # lavapipe: Vulkan on the CPU (lvp_icd.x86_64.json)
  libvulkan1               # the Vulkan loader
  libx11-6 libx11-xcb1 libxcursor1 libxi6 libxrandr2 libxkbcommon0 libxkbcommon-x11-0  # dlopen()ed by the viewer
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

SUDO=
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then
    SUDO=sudo
  else
    echo "install_viewer_deps.sh: need root to install: ${missing[*]}" >&2
    exit 1
  fi
fi

export DEBIAN_FRONTEND=noninteractive
log=$(mktemp)
trap 'rm -f "$log"' EXIT
if ! { $SUDO apt-get update -qq && $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"; } >"$log" 2>&1; then
  cat "$log" >&2
  echo "install_viewer_deps.sh: apt-get failed installing: ${missing[*]}" >&2
  exit 1
fi
echo "install_viewer_deps.sh: installed ${missing[*]}"
