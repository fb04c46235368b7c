#!/usr/bin/env bash
# The main job: set up, build, and run groovescope on the bundled demo scan (workbench when a
# display exists, otherwise a WAV file and a JSON report in the current folder).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
bash "$here/scripts/setup.sh"
cargo run --release --locked --manifest-path "$here/Cargo.toml" -- "$@"
