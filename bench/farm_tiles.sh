#!/bin/sh
# Space tiles of `vdbturb farm` on the Blender pair (docs/farm.md, "Space tiles"): an untiled transfer, the same
# transfer as 2x1 and 2x2 tiles (each array task's script run here in turn, no Slurm needed), the join, `measure` on
# all of them at the same tile borders, tests/farm/check_tiles.py, and each task's peak RSS and s/frame from its log.
#   bench/farm_tiles.sh [TILING ...]     default "2 2x2"; about 40 minutes on 2 cores with the untiled run
# Environment: BIN (default build/tools/vdbturb), WORK (default /tmp/vdbturb-farm-tiles), DATA (../shared/data),
# HALO (target voxels, default: farm plan's).
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=${BIN:-$ROOT/build/tools/vdbturb}
DATA=${DATA:-$ROOT/../shared/data}
WORK=${WORK:-/tmp/vdbturb-farm-tiles}
T="$DATA/blender-plume2-32/fluid_data_####.vdb"
S="$DATA/blender-plume2-128/fluid_data_####.vdb"
TILINGS=${*:-2 2x2}
HALOARG=""
[ -n "${HALO:-}" ] && HALOARG="--halo $HALO"
mkdir -p "$WORK"
rss() { sed -n 's/.*median \([0-9.]*\) s\/frame.*peak RSS \([0-9]*\) MB.*/\1 s\/frame, peak RSS \2 MB/p' "$1" | tail -1; }
for tiling in $TILINGS; do
  R="$WORK/t${tiling}_h${HALO:-default}"
  # Tile frames already in $R are kept (the tasks resume); delete WORK to start over.
  # shellcheck disable=SC2086
  "$BIN" farm plan --dir "$R/farm" --target "$T" --source "$S" --out "$R/joined/turb.####.vdb" --tiles "$tiling" \
    $HALOARG --cpus 2 | tee "$R.plan.txt"
  n=$(python3 -c "import json,sys; print(len(json.load(open(sys.argv[1]))['tasks']) - 1)" "$R/farm/plan.json")
  k=0
  while [ "$k" -lt "$n" ]; do
    SLURM_ARRAY_TASK_ID=$k sh "$R/farm/tiles.sbatch" 2>> "$R/farm/logs/tile_$k.log"
    echo "tile $k: $(rss "$R/farm/logs/tile_$k.log")"
    k=$((k + 1))
  done
  sh "$R/farm/join.sbatch" 2>> "$R/farm/logs/join.log"
  grep "farm join:" "$R/farm/logs/join.log" | tail -1
  borders=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['tiles']['borders'])" "$R/farm/plan.json")
  [ -f "$WORK/seq/turb.0030.vdb" ] || { "$BIN" transfer --target "$T" --source "$S" --out "$WORK/seq/turb.####.vdb" \
    --threads 2 2> "$WORK/seq.log"; echo "untiled: $(rss "$WORK/seq.log")"; }
  "$BIN" measure --output "$WORK/seq/turb.####.vdb" --target "$T" --source "$S" --no-spectra --no-structure \
    --tile-borders "$borders" -q > "$R/seq.measure.json"
  "$BIN" measure --output "$R/joined/turb.####.vdb" --target "$T" --source "$S" --no-spectra --no-structure -q \
    > "$R/joined.measure.json"
  python3 "$ROOT/tests/farm/check_tiles.py" "$R/farm/plan.json" "$R/seq.measure.json" "$R/joined.measure.json" || true
done
