#!/bin/sh
# The dry run's time estimate (turb::transferSecondsPerFrame): fits s/frame = c0 + c1 x output voxels + c2 x source
# voxels to every frame of a few transfers of different sizes and ratios, and prints the fit, each pair's measured
# and predicted total, and the worst frame's ratio. Run on an idle 2-core machine; record the result in
# docs/performance.md ("Time estimate") and the constants in libturb/src/core/Budget.cc.
#   bench/time_model.sh [--vdbturb BIN] [--work DIR]
set -eu
cd "$(dirname "$0")/.."
BIN=build/tools/vdbturb
WORK=/tmp/vdbturb-time-model
while [ $# -gt 0 ]; do
  case "$1" in
    --vdbturb) BIN=$2; shift 2 ;;
    --work) WORK=$2; shift 2 ;;
    *) echo "usage: $0 [--vdbturb BIN] [--work DIR]" >&2; exit 2 ;;
  esac
done
DATA=../shared/data
mkdir -p "$WORK"

# name target source frames
pair() {
  name=$1 t=$2 s=$3 frames=$4
  rm -rf "$WORK/$name"
  "$BIN" transfer --target "$t" --source "$s" --frames "$frames" --out "$WORK/$name/o.####.vdb" --threads 2 --json -q \
    > "$WORK/$name.jsonl"
  "$BIN" info "$t" --frames "$frames" --all-values --json -q > "$WORK/$name.target.json"
  "$BIN" info "$s" --all-values --json -q > "$WORK/$name.source.json"
}

[ -f "$WORK/proxy/p.0030.vdb" ] ||
  "$BIN" resample "$DATA/blender-steady-64/fluid_data_####.vdb" --down 4 --frames 91-120 --out "$WORK/proxy/p.####.vdb" -q
pair plume4 "$DATA/blender-plume-32/fluid_data_####.vdb" "$DATA/blender-plume-128/fluid_data_####.vdb" 1-10
pair plume2x4 "$DATA/blender-plume2-32/fluid_data_####.vdb" "$DATA/blender-plume2-128/fluid_data_####.vdb" 1-30
pair steady4 "$WORK/proxy/p.####.vdb" "$DATA/blender-steady-64/fluid_data_####.vdb" 91-120
[ -f "$WORK/half/h.0030.vdb" ] ||
  "$BIN" resample "$DATA/blender-plume2-128/fluid_data_####.vdb" --down 2 --frames 1-30 --out "$WORK/half/h.####.vdb" -q
pair plume2x2 "$WORK/half/h.####.vdb" "$DATA/blender-plume2-128/fluid_data_####.vdb" 1-30

python3 - "$WORK" <<'EOF'
import json, sys, os
work = sys.argv[1]
rows = []
for name in ("plume4", "plume2x4", "steady4", "plume2x2"):
    if not os.path.exists(f"{work}/{name}.jsonl"):
        continue
    frames = [json.loads(l) for l in open(f"{work}/{name}.jsonl") if l.strip()]
    frames = [f for f in frames if "seconds" in f and "frame" in f]
    tgt = {f["frame"]: f for f in json.load(open(f"{work}/{name}.target.json"))["files"]}
    src = json.load(open(f"{work}/{name}.source.json"))["files"]
    def vol(b):
        return (b[1][0] - b[0][0] + 1) * (b[1][1] - b[0][1] + 1) * (b[1][2] - b[0][2] + 1)
    svox = max(vol(f["held_box"]) for f in src if "held_box" in f)
    tv = [vol(tgt[1 if 1 in tgt else min(tgt)]["held_box"])]
    for f in frames:
        t = tgt.get(f["frame"])
        if not t or "held_box" not in t:
            continue
        ratio = f["ratio"]
        out = vol(t["held_box"]) * ratio ** 3
        rows.append((name, f["frame"], out, svox, f["seconds"]))
# Least squares for s = c0 + c1 out + c2 src (normal equations, 3x3).
X = [(1.0, r[2], r[3]) for r in rows]
y = [r[4] for r in rows]
A = [[sum(x[i] * x[j] for x in X) for j in range(3)] for i in range(3)]
b = [sum(x[i] * yy for x, yy in zip(X, y)) for i in range(3)]
import copy
M = [A[i] + [b[i]] for i in range(3)]
for i in range(3):
    p = max(range(i, 3), key=lambda r: abs(M[r][i]))
    M[i], M[p] = M[p], M[i]
    for r in range(3):
        if r != i:
            k = M[r][i] / M[i][i]
            M[r] = [a - k * c for a, c in zip(M[r], M[i])]
c = [M[i][3] / M[i][i] for i in range(3)]
print(f"fit: c0 {c[0]:.4g} s, c1 {c[1]:.4g} s per output voxel, c2 {c[2]:.4g} s per source voxel ({len(rows)} frames)")
worst = 1.0
for name in sorted(set(r[0] for r in rows)):
    rr = [r for r in rows if r[0] == name]
    meas = sum(r[4] for r in rr)
    pred = sum(c[0] + c[1] * r[2] + c[2] * r[3] for r in rr)
    fr = [max((c[0] + c[1] * r[2] + c[2] * r[3]) / r[4], r[4] / (c[0] + c[1] * r[2] + c[2] * r[3])) for r in rr]
    worst = max(worst, max(fr))
    print(f"{name}: {len(rr)} frames, measured {meas:.1f} s, predicted {pred:.1f} s ({pred / meas:.2f}x); "
          f"worst frame off by {max(fr):.2f}x")
print(f"worst frame over all pairs: {worst:.2f}x")
EOF
