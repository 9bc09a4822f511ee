#!/bin/sh
# vdbturb demo, run from the repository root after the build (tools/build.sh):
#   1. simulates the built-in `plume` at 16x16x24 (the low-res target) and `swirl` at 128x128x192 (the
#      high-res source) over the same 4 x 4 x 6 world domain;
#   2. transfers the swirl's turbulence onto the plume (`vdbturb transfer`) and measures it;
#   3. renders contact sheets (target | source | output: density, speed and LIC, vorticity) and prints their paths.
#
# Environment: VDBTURB (the binary, default build/tools/vdbturb), DEMO_OUT (default demo-out),
# DEMO_FRAMES (default 16 = 2/3 s; the 128x128x192 swirl costs about 7 s a frame on 2 idle cores),
# DEMO_THREADS (default 0 = all cores).
# Installed (cmake --install), it is PREFIX/share/vdbturb/demo.sh: it then runs PREFIX/bin/vdbturb and writes
# demo-out/ in the current directory.
set -eu
HERE="$(cd "$(dirname "$0")" && pwd)"
if [ -d "$HERE/../libturb" ]; then
  cd "$HERE/.."
  DEFAULT_BIN=build/tools/vdbturb
else
  DEFAULT_BIN="$HERE/../../bin/vdbturb"
fi

BIN="${VDBTURB:-$DEFAULT_BIN}"
OUT="${DEMO_OUT:-demo-out}"
FRAMES="${DEMO_FRAMES:-16}"
THREADS="${DEMO_THREADS:-0}"

if [ ! -x "$BIN" ]; then
  echo "demo: $BIN not found; build first (tools/build.sh) or set VDBTURB" >&2
  exit 2
fi
case "$FRAMES" in
  ''|*[!0-9]*) echo "demo: DEMO_FRAMES must be a number" >&2; exit 2 ;;
esac
if [ "$FRAMES" -lt 3 ]; then
  echo "demo: DEMO_FRAMES must be at least 3" >&2
  exit 2
fi

TARGET="$OUT/target/plume.####.vdb"
SOURCE="$OUT/source/swirl.####.vdb"
OUTPUT="$OUT/output/turb.####.vdb"

echo "demo: simulating plume 16x16x24 and swirl 128x128x192, $FRAMES frames each, into $OUT/" >&2
"$BIN" sim plume --res 16x16x24 --frames "$FRAMES" --seed 1 --out "$TARGET" --threads "$THREADS"
# One substep per frame keeps the high-res source within a few minutes; the fastest voxels then cross up
# to about 9 voxels a frame (6.8 units/s measured), which MacCormack with its limiter takes stably.
"$BIN" sim swirl --res 128x128x192 --frames "$FRAMES" --seed 2 --max-substeps 1 --out "$SOURCE" --threads "$THREADS"

# The main job: the swirl's turbulence transferred onto the plume's motion (Sato et al. 2018), then measured.
echo "demo: transferring the swirl's turbulence onto the plume" >&2
"$BIN" transfer --target "$TARGET" --source "$SOURCE" --out "$OUTPUT" --threads "$THREADS"
echo "demo: measuring the result (lf_err, hf_ratio, div_rel, block, tcoh, spectra)" >&2
"$BIN" measure --output "$OUTPUT" --target "$TARGET" --source "$SOURCE" --plot "$OUT/plots" \
  --threads "$THREADS" > "$OUT/measure.jsonl"

# Three frames spread over the run: a third, two thirds, the last.
F1=$((FRAMES / 3)); F2=$((2 * FRAMES / 3)); F3=$FRAMES
[ "$F1" -ge 1 ] || F1=1

set -- "target=$TARGET" "source=$SOURCE"
if ls "$OUT"/output/turb.*.vdb >/dev/null 2>&1; then
  set -- "$@" "output=$OUTPUT"
fi

"$BIN" preview "$@" --mode density --frames "$F1,$F2,$F3" --width 256 --threads "$THREADS" \
  --title "vdbturb demo: density (front view)" --sheet "$OUT/sheet_density.png"
"$BIN" preview "$@" --mode speed,lic --frames "$F3" --width 256 --threads "$THREADS" \
  --title "vdbturb demo: speed and LIC, mid slice, frame $F3" --sheet "$OUT/sheet_velocity.png"
# Vorticity shows what the numbers can miss: the patch lattice, streaks, hot spots (docs/transfer.md).
"$BIN" preview "$@" --mode vorticity --frames "$F1,$F2,$F3" --width 256 --threads "$THREADS" \
  --title "vdbturb demo: vorticity, mid slice" --sheet "$OUT/sheet_vorticity.png"

echo "demo: results" >&2
echo "$OUT/sheet_density.png"
echo "$OUT/sheet_velocity.png"
echo "$OUT/sheet_vorticity.png"
echo "$OUT/plots/metrics.png"
echo "$OUT/measure.jsonl"
