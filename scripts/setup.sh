#!/usr/bin/env bash
# Installs the Debian packages groovescope needs to build, run the workbench and run the headless
# tests; does nothing when they are all present already.
set -euo pipefail
PKGS=(pkg-config libasound2-dev
      mesa-vulkan-drivers libvulkan1 libegl1 libegl-mesa0 libgl1-mesa-dri
      libx11-6 libxcursor1 libxi6 libxrandr2 libxkbcommon-x11-0 libfontconfig1
      xvfb xauth imagemagick
      # The workbench's file dialogs where no desktop portal answers (rfd falls back to it).
      zenity
      # Speech for `groovescope accuracy` (skipped there when missing).
      espeak-ng
      # FFmpeg and libclang (bindgen) for the `video` feature (import-video, Import video…).
      libavcodec-dev libavformat-dev libavutil-dev libswscale-dev libswresample-dev
      libavfilter-dev libavdevice-dev libclang-dev
      # A C++ compiler for libFuzzer (scripts/fuzz.sh).
      g++)
missing=()
for p in "${PKGS[@]}"; do
    dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if ((${#missing[@]} == 0)); then
    exit 0
fi
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
echo "installing: ${missing[*]}" >&2
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
