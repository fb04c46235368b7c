#!/usr/bin/env bash
# The whole-side figures README quotes (not a test; takes about 30 minutes on 2 cores):
#  1. memory: peak RSS of a 2,000-group reconstruct against a 20-group one (small frames);
#  2. speed: groups/s on one core on the dual-focus and depth paths (1280x1024 frames, decode
#     included), and the projected wall time of a 3-minute 78 side on 1, 8 and 64 cores;
#  3. the Zarr store against the PNG folder: bytes on disk and decode seconds per group;
#  4. the merge of a side: peak RSS per group and per native sample, from merges of two-shard
#     plans of small scans of two frame widths, projected to a 3-minute side.
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
# long SRC N DST: N groups, SRC's rendered ones repeated (hard links), so every group is real
# work.
long() {
    [ -d "$3" ] && return
    mkdir "$3"
    cp "$1/scan.toml" "$3/"
    local rendered=("$1"/g*)
    for g in $(seq 0 $(($2 - 1))); do
        dst="$3/$(printf 'g%05d' "$g")"
        mkdir "$dst"
        ln "${rendered[$((g % ${#rendered[@]}))]}"/* "$dst/"
    done
}
long "$work/small" 2000 "$work/long"
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

# --- 4. the merge of a side -------------------------------------------------------------------
# A merge holds every group's signals and then decodes the whole clip at once, so its memory
# grows with the groups and with the native samples. Two frame widths give two samples-per-group
# ratios (160 px: 140 µm a group; 480 px: 460 µm, a paper-optics group's length); two plan
# sizes of each give the growth, solved for bytes a group and a native sample.
if ! [ -d "$work/wide" ]; then
    sed 's/^width_px = 160/width_px = 480/' scripts/small-side-synth.toml >"$work/wide-synth.toml"
    "$gs" synth --preset dual-focus --config "$work/wide-synth.toml" --tone 1000 --duration 0.05 \
        --max-groups 40 --out "$work/wide" --quiet
fi
merge_kb() { # SCAN TAG -> "peak_kB native_samples groups"
    local parts="$work/parts-$2"
    rm -rf "$parts"
    mkdir "$parts"
    "$gs" plan "$1" --shards 2 --out "$parts/plan.json" --probe-groups 0 >/dev/null
    "$gs" reconstruct "$1" --plan "$parts/plan.json" --shard 0 --out "$parts/p0/" --quiet 2>/dev/null &
    "$gs" reconstruct "$1" --plan "$parts/plan.json" --shard 1 --out "$parts/p1/" --quiet 2>/dev/null
    wait
    /usr/bin/time -v "$gs" merge "$parts/p0" "$parts/p1" --out "$parts/side.wav" \
        --report "$parts/side.json" --quiet 2>"$parts/time.txt"
    echo "$(peak_kb "$parts/time.txt") $(json "round(r['duration_secs'] * r['native_rate_hz'])" "$parts/side.json") $(json "len(r['groups'])" "$parts/side.json")"
}
long "$work/small" 10000 "$work/small-10k"
long "$work/small" 20000 "$work/small-20k"
long "$work/wide" 5000 "$work/wide-5k"
long "$work/wide" 10000 "$work/wide-10k"
read -r a1 n1 g1 <<<"$(merge_kb "$work/small-10k" s10)"
read -r a2 n2 g2 <<<"$(merge_kb "$work/small-20k" s20)"
read -r b1 m1 h1 <<<"$(merge_kb "$work/wide-5k" w5)"
read -r b2 m2 h2 <<<"$(merge_kb "$work/wide-10k" w10)"
echo "merge peak RSS: 160 px groups ${g1}: ${a1} kB, ${g2}: ${a2} kB; 480 px groups ${h1}: ${b1} kB, ${h2}: ${b2} kB"
python3 -c "
# kB growth = groups * per_group + samples * per_sample, from the two pairs of plans.
(a, b), (c, d) = ($g2 - $g1, $n2 - $n1), ($h2 - $h1, $m2 - $m1)
y1, y2 = ($a2 - $a1) * 1024, ($b2 - $b1) * 1024
det = a * d - b * c
per_group, per_sample = (y1 * d - b * y2) / det, (a * y2 - c * y1) / det
groups, samples = $side_groups, $side_groups * ($m2 - $m1) / ($h2 - $h1)
print(f'  {per_group:.0f} B a group + {per_sample:.0f} B a native sample; a 3-minute side '
      f'({groups} groups, {samples / 1e6:.1f} M native samples): {(groups * per_group + samples * per_sample) / 2**30:.1f} GiB')"
