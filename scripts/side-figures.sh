#!/usr/bin/env bash
# The whole-side figures README quotes (not a test; takes about 15 minutes on 2 cores):
#  1. memory: peak RSS of a 2,000-group reconstruct against a 20-group one (small frames);
#  2. speed: groups/s on one core on the dual-focus and depth paths (1280x1024 frames, decode
#     included), and the projected wall time of a 3-minute 78 side on 1, 8 and 64 cores;
#  3. the Zarr store against the PNG folder: bytes on disk and decode seconds per group.
#   bash scripts/side-figures.sh [WORKDIR]     (GROOVESCOPE=path: that binary, no release build)
set -euo pipefail
cd "$(dirname "$0")/.."
if ! [ -x /usr/bin/time ]; then apt-get install -y -qq time >/dev/null; fi
if [ -n "${GROOVESCOPE:-}" ]; then
    gs=$GROOVESCOPE   # e.g. target/debug/groovescope; say so when quoting the figures
else
    cargo build --locked --release --quiet
    gs="$PWD/target/release/groovescope"
fi
work=${1:-$(mktemp -d /tmp/groovescope-figures.XXXXXX)}
mkdir -p "$work"
json() { python3 -c "import json,sys; r=json.load(open(sys.argv[1])); print($1)" "$2"; }
peak_kb() { sed -n 's/.*Maximum resident set size (kbytes): //p' "$1"; }

# --- 1. memory --------------------------------------------------------------------------------
if ! [ -d "$work/small" ]; then
    "$gs" synth --preset dual-focus --config "scripts/small-side-synth.toml" --tone 1000 --duration 0.01 \
        --max-groups 40 --out "$work/small" --quiet
fi
# 2,000 groups: the 40 rendered ones repeated (hard links), so every group is real work.
if ! [ -d "$work/long" ]; then
    mkdir "$work/long"
    cp "$work/small/scan.toml" "$work/long/"
    rendered=("$work/small"/g*)
    for g in $(seq 0 1999); do
        dst="$work/long/$(printf 'g%05d' "$g")"
        mkdir "$dst"
        ln "${rendered[$((g % ${#rendered[@]}))]}"/* "$dst/"
    done
fi
rm -f "$work"/mem*.wav
/usr/bin/time -v "$gs" reconstruct "$work/long" --groups 20 --out "$work/mem20.wav" --quiet 2>"$work/mem20.txt"
/usr/bin/time -v "$gs" reconstruct "$work/long" --out "$work/mem2000.wav" --quiet 2>"$work/mem2000.txt"
m20=$(peak_kb "$work/mem20.txt")
m2000=$(peak_kb "$work/mem2000.txt")
echo "load average while measuring: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "memory: peak RSS 20 groups ${m20} kB, 2000 groups ${m2000} kB ($(echo "scale=1; 100 * ($m2000 - $m20) / $m20" | bc) %)"

# --- 2. speed on one core ---------------------------------------------------------------------
if ! [ -d "$work/dual" ]; then
    "$gs" synth --preset dual-focus --tone 1000 --duration 0.02 --max-groups 8 --out "$work/dual" --quiet
fi
if ! [ -d "$work/depth" ]; then
    "$gs" synth --preset paper --tone 1000 --duration 0.02 --max-groups 3 --out "$work/depth" --quiet
fi
side_groups=$(python3 -c "print(round(180 * 2 * 3.141592653589793 * 78 / 60 * 115 / 0.4602))")
for path in dual depth; do
    rm -f "$work/$path-1.wav"
    # CPU seconds (user + system) of a one-thread run: a per-core figure that other tenants'
    # load on this machine does not inflate the way it does wall time.
    RAYON_NUM_THREADS=1 /usr/bin/time -v "$gs" reconstruct "$work/$path" --out "$work/$path-1.wav" \
        --report "$work/$path-1.json" --force --quiet 2>"$work/$path-1.time"
    groups=$(json "len(r['groups'])" "$work/$path-1.json")
    cpu=$(python3 -c "
import re,sys
t=open(sys.argv[1]).read()
u=float(re.search(r'User time \(seconds\): ([0-9.]+)',t).group(1))
s=float(re.search(r'System time \(seconds\): ([0-9.]+)',t).group(1))
print(u+s)" "$work/$path-1.time")
    spg=$(python3 -c "print($cpu / $groups)")
    echo "speed ($path path, 1280x1024, one thread, decode included): $(printf '%.3f' "$spg") CPU s a group, $(python3 -c "print(f'{1/$spg:.2f}')") groups/s per core ($groups groups)"
    for cores in 1 8 64; do
        # Ideal shard scaling plus each shard's 64 groups of slope history.
        python3 -c "
g=$side_groups; c=$cores; s=$spg
per=(g/c + (64 if c>1 else 0))*s
print(f'  3-minute 78 side ({g} groups) on {c:2d} cores: {per/3600:.1f} h')"
    done
done

# --- 3. Zarr against the PNG folder -----------------------------------------------------------
for path in dual depth; do
    rm -rf "$work/$path.zarr"
    "$gs" pack "$work/$path" --out "$work/$path.zarr" --quiet
    png=$(du -sb "$work/$path" | cut -f1)
    zarr=$(du -sb "$work/$path.zarr" | cut -f1)
    for form in "$path" "$path.zarr"; do
        rm -f "$work/dec.wav"
        "$gs" reconstruct "$work/$form" --out "$work/dec.wav" --report "$work/dec.json" --force --quiet
        echo "  $form: $(json "f\"{r['timings']['load_secs'] / len(r['groups']):.3f} s decoding a group (loader thread)\"" "$work/dec.json")"
        cp "$work/dec.wav" "$work/$form.wav"
    done
    cmp "$work/$path.wav" "$work/$path.zarr.wav"
    echo "zarr ($path scan): folder $png bytes, store $zarr bytes ($(echo "scale=1; 100 * $zarr / $png" | bc) %); the same WAV from both"
done
