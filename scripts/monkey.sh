#!/usr/bin/env bash
# The long monkey test of the workbench: 200 seeded sequences of 300 random operator events
# (tests/monkey.rs; `cargo test` runs a short version). Override with
# `scripts/monkey.sh SEQUENCES EVENTS`; replay one sequence with GROOVESCOPE_MONKEY_SEED=N.
set -euo pipefail
cd "$(dirname "$0")/.."
sequences="${1:-200}"
events="${2:-300}"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
chmod 700 "$XDG_RUNTIME_DIR"
GROOVESCOPE_MONKEY="${sequences}x${events}" cargo test --locked --test monkey -- --nocapture
