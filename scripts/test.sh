#!/usr/bin/env bash
# The test command: formatting, lints, the whole test suite (GUI tests render headless), docs.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
chmod 700 "$XDG_RUNTIME_DIR"
# A silent null sound card so playback tests need no hardware.
alsa_conf="$(mktemp)"
printf '</usr/share/alsa/alsa.conf>\npcm.!default { type null }\n' >"$alsa_conf"
export ALSA_CONFIG_PATH="$alsa_conf"
cargo fmt --all -- --check
cargo clippy --locked --all-targets -- -D warnings
cargo test --locked
RUSTDOCFLAGS="-D warnings" cargo doc --locked --no-deps
# The workbench for real: a window under Xvfb, one screenshot taken and checked.
shot_dir="$(mktemp -d)"
SCREENSHOT_DIR="$shot_dir" VIEWS=overview bash scripts/screenshots.sh
test -s "$shot_dir/overview.png"
echo "workbench screenshot under Xvfb: $(wc -c <"$shot_dir/overview.png") bytes"
