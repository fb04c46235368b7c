#!/usr/bin/env bash
# Fuzzes every parser and loader (fuzz/src/targets.rs) with libFuzzer for SECONDS each
# (default 10), or for RUNS executions each with `scripts/fuzz.sh --runs RUNS`.
#
# Stable Rust: the binary links libFuzzer through libfuzzer-sys (built from its bundled C++
# source) and is compiled with LLVM's SanitizerCoverage passes, which rustc's stable `-C
# passes` / `-C llvm-args` options switch on, so libFuzzer is coverage-guided. No nightly
# and no RUSTC_BOOTSTRAP: only AddressSanitizer (`-Zsanitizer`) needs nightly, and safe Rust
# does not need it to find panics, overflows (overflow checks are on), hangs (-timeout) and
# runaway memory (-rss_limit_mb / -malloc_limit_mb).
#
# New inputs go to a scratch corpus, not the repository; crashes are written to
# fuzz/artifacts/TARGET/ and the script fails. Keep a fixed crash as a regression seed:
# copy it into fuzz/corpus/TARGET/ (tests/hostile_corpus.rs replays every seed).
set -euo pipefail
cd "$(dirname "$0")/.."
mode=time
budget="${1:-10}"
if [ "${1:-}" = "--runs" ]; then mode=runs; budget="${2:?--runs needs a count}"; fi
only="${GROOVESCOPE_FUZZ_ONLY:-}"

export RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing"
export CARGO_TARGET_DIR="$PWD/fuzz/target"
if [ "${GROOVESCOPE_FUZZ_BUILD_ONLY:-}" = 1 ]; then run_targets=0; else run_targets=1; fi
# An explicit --target keeps the instrumentation off build scripts and proc macros.
host="$(rustc -vV | sed -n 's/^host: //p')"
cargo build --locked --release --manifest-path fuzz/Cargo.toml --target "$host" --bin groovescope
bin="$CARGO_TARGET_DIR/$host/release/groovescope"
if [ "$run_targets" = 0 ]; then exit 0; fi

scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
status=0
for dir in fuzz/corpus/*/; do
    name="$(basename "$dir")"
    if [ -n "$only" ] && [ "$name" != "$only" ]; then continue; fi
    mkdir -p "$scratch/$name" "fuzz/artifacts/$name"
    if [ "$mode" = runs ]; then limit=(-runs="$budget"); else limit=(-max_total_time="$budget"); fi
    log="$scratch/$name.log"
    if GROOVESCOPE_FUZZ_TARGET="$name" "$bin" "${limit[@]}" -timeout=10 -rss_limit_mb=2048 \
        -malloc_limit_mb=1024 -max_len=65536 -print_final_stats=1 \
        -artifact_prefix="fuzz/artifacts/$name/" "$scratch/$name" "$dir" >"$log" 2>&1; then
        result=ok
    else
        result=CRASH
        status=1
        tail -n 40 "$log"
    fi
    runs=$(awk '/stat::number_of_executed_units:/{print $2}' "$log")
    cov=$(grep -o 'cov: [0-9]*' "$log" | tail -n 1 | awk '{print $2}')
    rate=$(awk '/stat::average_exec_per_sec:/{print $2}' "$log")
    secs=$(awk '/stat::slowest_unit_time_sec:/{print $2}' "$log")
    echo "fuzz $name: ${runs:-?} executions (${rate:-?}/s), coverage ${cov:-?} edges, slowest input ${secs:-?} s: $result"
done
exit "$status"
