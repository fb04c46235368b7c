#!/usr/bin/env bash
# The test command: formatting, lints, the whole test suite (GUI tests render headless), the
# video-import tests with the `video` feature on, docs.
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
# The `video` feature (FFmpeg): lints, then only its own tests to keep CI time down.
cargo clippy --locked --all-targets --features video -- -D warnings
cargo test --locked --features video --lib -- io::video app::import_video
cargo test --locked --features video --test import_video
# Every fuzz target briefly (the long runs and their figures: README, "Hostile input").
bash scripts/fuzz.sh 5
RUSTDOCFLAGS="-D warnings" cargo doc --locked --no-deps
RUSTDOCFLAGS="-D warnings" cargo doc --locked --no-deps --features video
# The workbench for real: a window under Xvfb, one screenshot taken and checked.
shot_dir="$(mktemp -d)"
SCREENSHOT_DIR="$shot_dir" VIEWS=overview bash scripts/screenshots.sh
test -s "$shot_dir/overview.png"
echo "workbench screenshot under Xvfb: $(wc -c <"$shot_dir/overview.png") bytes"
# And with no zenity and no desktop portal, Export WAV… shows the in-app path field.
OUT_DIR="$shot_dir" bash scripts/dialog-fallback.sh
