#!/usr/bin/env bash
# The main job: set up, build, and run groovescope on the bundled demo (the workbench when a
# display exists; otherwise the demo still, assets/demo-still, decoded to a WAV file and a JSON
# report in the current folder, then played when aplay finds a sound card).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
bash "$here/scripts/setup.sh"
if (($# > 0)) || [ -n "${DISPLAY:-}${WAYLAND_DISPLAY:-}" ]; then
    exec cargo run --release --locked --manifest-path "$here/Cargo.toml" -- "$@"
fi
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
cargo run --release --locked --manifest-path "$here/Cargo.toml" | tee "$log"
wav="$(sed -n 's/^wrote \(.*\.wav\) (.*/\1/p' "$log" | head -n 1)"
if [ -n "$wav" ] && command -v aplay >/dev/null 2>&1 && aplay -l 2>/dev/null | grep -q '^card'; then
    echo "playing $wav"
    aplay -q "$wav" || echo "could not play $wav (the WAV file is kept)" >&2
fi
