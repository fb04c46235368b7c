#!/usr/bin/env bash
# Runs the workbench for real in an X window under Xvfb and saves a screenshot of each view
# into screenshots/ (the app captures itself: GROOVESCOPE_SCREENSHOT, then closes). Every view
# is taken after the clip is reconstructed, so the health strip is filled; the waveform after a
# second reconstruction with the "noisy" symptom preset, so it shows the A/B pair; "ab" is the
# waveform view under the "Compare methods" window, fused against flow.
#
# usage: scripts/screenshots.sh [SCAN] [DEPTH_SCAN]
#   SCAN        scan for every view but depth and still (default assets/demo, a dual-focus
#               scan)
#   DEPTH_SCAN  scan on the depth path (no [dual_focus]) for the depth view; default: one rendered
#               now with `groovescope synth --preset demo` (6 groups of a 440 Hz tone)
# env: SCREENSHOT_DIR (default screenshots), GROOVESCOPE_BIN (default target/debug/groovescope, built when missing), VIEWS (names).
set -euo pipefail
cd "$(dirname "$0")/.."
scan="${1:-assets/demo}"
depth="${2:-}"
bin="${GROOVESCOPE_BIN:-${CARGO_TARGET_DIR:-target}/debug/groovescope}"
if [ ! -x "$bin" ]; then
    cargo build --locked
fi
for tool in Xvfb; do
    command -v "$tool" >/dev/null || { echo "missing $tool (apt-get install xvfb)" >&2; exit 1; }
done
outdir="${SCREENSHOT_DIR:-screenshots}"
mkdir -p "$outdir"
XDG_RUNTIME_DIR="$(mktemp -d)"
chmod 700 "$XDG_RUNTIME_DIR"
export XDG_RUNTIME_DIR
GROOVESCOPE_CONFIG_DIR="$(mktemp -d)"   # leave the user's recent-scans list alone
export GROOVESCOPE_CONFIG_DIR
export GROOVESCOPE_AUDIO_DEVICE=off
display=":${XVFB_DISPLAY:-99}"
Xvfb "$display" -screen 0 1600x1000x24 -nolisten tcp >/dev/null 2>&1 &
xvfb_pid=$!
trap 'kill "$xvfb_pid" 2>/dev/null || true; rm -rf "$XDG_RUNTIME_DIR" "$GROOVESCOPE_CONFIG_DIR"' EXIT
export DISPLAY="$display"
sleep 1
status=0
for view in ${VIEWS:-overview frame flow hough stripes depth orientation edges waveform metadata ab still}; do
    s="$scan"
    if [ "$view" = depth ]; then
        if [ -z "$depth" ]; then
            depth="$GROOVESCOPE_CONFIG_DIR/depth-scan"
            "$bin" synth --preset demo --tone 440 --duration 0.05 --max-groups 6 --quiet --out "$depth"
        fi
        s="$depth"
    fi
    out="$outdir/$view.png"
    echo "== $view ($s) -> $out"
    compare=(GROOVESCOPE_RECONSTRUCT=1 GROOVESCOPE_VIEW="$view")
    if [ "$view" = waveform ]; then compare+=(GROOVESCOPE_COMPARE=noisy); fi
    if [ "$view" = ab ]; then
        compare=(GROOVESCOPE_VIEW=waveform GROOVESCOPE_COMPARE_METHODS=fused,flow)
    fi
    if [ "$view" = still ]; then
        # The bundled still strip in the still window, its speech groove decoded.
        compare=(GROOVESCOPE_VIEW=overview)
        s=assets/demo-still/still.png
    fi
    if ! env "${compare[@]}" \
        GROOVESCOPE_SCREENSHOT="$out" timeout 900 "$bin" gui "$s"; then
        echo "screenshot of $view failed" >&2
        status=1
    fi
done
# Export WAV… on a machine with no file dialog (no zenity, no portal): the in-app path field.
if [ -z "${VIEWS:-}" ]; then
    OUT_DIR="$outdir" XVFB_DISPLAY=98 bash scripts/dialog-fallback.sh "$scan" || status=1
fi
exit "$status"
