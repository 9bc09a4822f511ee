#!/bin/sh
# Issue 44's profile on pairs whose smoke is dense: where a transfer's time goes when the smoke fills much of
# the target's box and most of the source's, against Blender 3.4's noise up-res (x8) of the same target, base sim
# included, timed in the same run. Two pairs in the paper's 16x16x24 -> 128x128x192 configuration (a 4x4x6 world):
#
#   heavy-a: a wide fast plume (emitter radius 1.0, speed 4) -> the two-jet swirl with wide fast jets (0.7, 12)
#   heavy-b: the same target -> the paper pair's two-jet swirl (0.4, 8), lighter, as bench/blender_pairs.sh bakes it
#
#   bench/heavy_pairs.sh [--work DIR] [--vdbturb BIN] [--frames N] [--pairs "heavy-a heavy-b"] [--no-blender-time]
#
# Prints, per pair: the smoke's share of the target's box and of the source's at the last frame, the transfer's
# wall and CPU seconds against Blender's noise bake's, s/frame at frame 5 and at the last frame, and each stage's
# seconds per frame (the --json steps_s) at frames 5, 15 and the last, with their sum over the shot. Bakes are kept
# in WORK and reused; Blender's noise bake runs again each time (its time is the comparison).
set -eu

ROOT=$(cd "$(dirname "$0")/.." && pwd)
SCENES="$ROOT/bench/blender"
WORK="${TMPDIR:-/tmp}/vdbturb-heavy"
BIN="$ROOT/build/tools/vdbturb"
FRAMES=30
PAIRS="heavy-a heavy-b"
TIME_BLENDER=1
while [ $# -gt 0 ]; do
    case "$1" in
    --work) WORK=$2; shift 2 ;;
    --vdbturb) BIN=$2; shift 2 ;;
    --frames) FRAMES=$2; shift 2 ;;
    --pairs) PAIRS=$2; shift 2 ;;
    --no-blender-time) TIME_BLENDER=0; shift ;;
    -h|--help) sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "heavy_pairs: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
command -v blender >/dev/null 2>&1 || { echo "heavy_pairs: needs blender (Debian 12: apt-get install blender)" >&2; exit 1; }
mkdir -p "$WORK"
LAST=$(printf '%04d' "$FRAMES")
log() { printf 'heavy_pairs: %s\n' "$*" >&2; }

# cpu_time CMD...: runs it, prints "WALL CPU" seconds (user + system of it and its children).
cpu_time() {
    /usr/bin/time -f '%e %U %S' -o "$WORK/time.txt" "$@" > "$WORK/last.log" 2>&1 || { cat "$WORK/last.log" >&2; exit 1; }
    awk '{ printf "%.1f %.1f", $1, $2 + $3 }' "$WORK/time.txt"
}

# The target with Blender's noise: its base sim is the transfer's target, its noise the comparison.
noise_bake() {
    rm -rf "$WORK/target"
    # In WORK: Blender's noise writes its waveletNoiseTile.bin into the current folder.
    cd "$WORK" && cpu_time blender -b --factory-startup --python "$SCENES/plume_noise.py" -- "$WORK/target" "$FRAMES" 8 24 0 1.0 4
}
source_bake() { # source_bake NAME SPEED RADIUS
    dir="$WORK/$1"
    [ -f "$dir/data/fluid_data_$LAST.vdb" ] && return 0
    log "baking the source $1 (128x128x192, $FRAMES frames)"
    rm -rf "$dir"
    blender -b --factory-startup --python "$SCENES/two_jet_swirl.py" -- 192 "$dir" "$FRAMES" "$2" 0 "$3" > "$WORK/$1.log" 2>&1
}

blender_time=""
if [ "$TIME_BLENDER" = 1 ] || [ ! -f "$WORK/target/data/fluid_data_$LAST.vdb" ]; then
    log "baking the target with Blender's noise x8 (timed)"
    blender_time=$(noise_bake)
fi
source_bake swirl_heavy 12 0.7
source_bake swirl_paper 8 0.4

# smoke_share FILE NX NY NZ: the share of the simulation's NXxNYxNZ cells whose density is above 1e-3.
smoke_share() {
    /usr/bin/python3 - "$@" <<'PY'
import sys
import numpy as np
import pyopenvdb as vdb
g = vdb.read(sys.argv[1], "density")
lo, hi = g.evalActiveVoxelBoundingBox()
a = np.zeros([hi[i] - lo[i] + 1 for i in range(3)], dtype=np.float32)
g.copyToArray(a, ijk=lo)
cells = int(sys.argv[2]) * int(sys.argv[3]) * int(sys.argv[4])
n = int((a > 1e-3).sum())
print("%.2f (%d of %d cells)" % (n / cells, n, cells))
PY
}

for pair in $PAIRS; do
    case "$pair" in
    heavy-a) src=swirl_heavy ;;
    heavy-b) src=swirl_paper ;;
    *) log "unknown pair $pair"; exit 2 ;;
    esac
    T="$WORK/target/data/fluid_data_####.vdb"; S="$WORK/$src/data/fluid_data_####.vdb"
    out="$WORK/out-$pair"; rm -rf "$out"
    t=$(cpu_time "$BIN" transfer --target "$T" --source "$S" --frames "1-$FRAMES" --out "$out/o.####.vdb" --json -q)
    cp "$WORK/last.log" "$WORK/$pair.json"
    echo "== $pair: target $T -> source $S, $FRAMES frames"
    echo "target smoke share at frame $FRAMES: $(smoke_share "$WORK/target/data/fluid_data_$LAST.vdb" 16 16 24)"
    echo "source smoke share at frame $FRAMES: $(smoke_share "$WORK/$src/data/fluid_data_$LAST.vdb" 128 128 192)"
    echo "transfer: $t (wall s, CPU s)${blender_time:+; Blender noise x8 (base sim included): $blender_time}"
    python3 - "$WORK/$pair.json" "$FRAMES" "$t" "$blender_time" <<'PY'
import json, sys
frames = [json.loads(l) for l in open(sys.argv[1]) if l.startswith("{")]
per = [f for f in frames if "steps_s" in f]
last = int(sys.argv[2])
by = {f["frame"]: f for f in per}
t = sys.argv[3].split()
if sys.argv[4]:
    b = sys.argv[4].split()
    print("ratio to Blender's noise: %.2fx wall, %.2fx CPU" % (float(t[0]) / float(b[0]), float(t[1]) / float(b[1])))
f5, fl = by.get(5), by.get(last)
if f5 and fl:
    print("s/frame: frame 5 %.2f, frame %d %.2f (x%.2f)" % (f5["seconds"], last, fl["seconds"], fl["seconds"] / f5["seconds"]))
stages = sorted({k for f in per for k in f["steps_s"] if k != "total"})
cols = [c for c in (5, 15, last) if c in by]
print("%-14s" % "stage" + "".join("%10s" % ("f%d" % c) for c in cols) + "%12s" % "sum")
for s in stages:
    print("%-14s" % s + "".join("%10.2f" % by[c]["steps_s"].get(s, 0.0) for c in cols) +
          "%12.1f" % sum(f["steps_s"].get(s, 0.0) for f in per))
PY
done
