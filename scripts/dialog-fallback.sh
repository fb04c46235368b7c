#!/usr/bin/env bash
# The workbench for real under Xvfb on a machine with no zenity and no desktop portal (PATH
# without zenity, no session bus): Export WAV… must say that no file dialog can open and show
# the in-app path field, not nothing. The app opens the dialog as its menu item does
# (GROOVESCOPE_DIALOG=export-wav, once the clip is reconstructed) and saves a screenshot of what
# came up; this script checks the message and keeps the picture.
#
# usage: scripts/dialog-fallback.sh [SCAN]   (default assets/demo)
# env: GROOVESCOPE_BIN (default target/debug/groovescope, built when missing), OUT_DIR (where the
#      screenshot goes; default a temporary folder).
set -euo pipefail
cd "$(dirname "$0")/.."
scan="${1:-assets/demo}"
bin="${GROOVESCOPE_BIN:-${CARGO_TARGET_DIR:-target}/debug/groovescope}"
if [ ! -x "$bin" ]; then
    cargo build --locked
fi
command -v Xvfb >/dev/null || { echo "missing Xvfb (apt-get install xvfb)" >&2; exit 1; }
work="$(mktemp -d)"
out_dir="${OUT_DIR:-$work}"
mkdir -p "$out_dir"
runtime="$work/runtime"
mkdir -m 700 "$runtime"
no_tools="$work/no-tools"   # an empty PATH: no zenity
mkdir "$no_tools"
display=":${XVFB_DISPLAY:-98}"
Xvfb "$display" -screen 0 1600x1000x24 -nolisten tcp >/dev/null 2>&1 &
xvfb_pid=$!
trap 'kill "$xvfb_pid" 2>/dev/null || true; rm -rf "$runtime" "$no_tools" "$work/config"' EXIT
sleep 1
shot="$out_dir/dialog-fallback.png"
rm -f "$shot"
status=0
bin_path="$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")"
timeout 900 env -u DBUS_SESSION_BUS_ADDRESS PATH="$no_tools" DISPLAY="$display" \
    XDG_RUNTIME_DIR="$runtime" GROOVESCOPE_CONFIG_DIR="$work/config" GROOVESCOPE_AUDIO_DEVICE=off \
    GROOVESCOPE_VIEW=waveform GROOVESCOPE_DIALOG=export-wav GROOVESCOPE_SCREENSHOT="$shot" \
    "$bin_path" gui "$scan" 2>"$work/stderr" || status=$?
if [ "$status" != 0 ]; then
    cat "$work/stderr" >&2
    echo "the workbench failed under Xvfb (exit $status)" >&2
    exit 1
fi
if ! grep -q "Export WAV: no file dialog can open here" "$work/stderr"; then
    cat "$work/stderr" >&2
    echo "Export WAV… without zenity did not say that no file dialog can open" >&2
    exit 1
fi
test -s "$shot"
echo "Export WAV… with no zenity and no portal: the app says so and shows the path field ($shot)"
