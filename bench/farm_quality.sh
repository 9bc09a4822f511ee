#!/bin/sh
# Seam quality of `vdbturb farm` time chunks on the Blender pair (docs/farm.md, "Measured"): a sequential transfer
# (holding the whole domains, as the chunks do, so that chunk 0 is bit-identical to it),
# the same transfer as N chunks (each array task's script run here in turn, no Slurm needed), the join, `measure`
# on both, and tests/farm/check_farm.py (which prints the seam frames' tcoh against the sequential median and the
# hf_ratio range).
#   bench/farm_quality.sh [CHUNKS] [PREROLL] [OVERLAP]     defaults 2 8 10; about 2 minutes on 2 idle cores plus the sequential run
# Environment: BIN (default build/tools/vdbturb), WORK (default /tmp/vdbturb-farm-quality), DATA (../shared/data);
# TARGET and SOURCE (patterns) run another pair than the Blender one (the paper configuration: bench/farm_quality.sh
# with TARGET=.../plume.####.vdb SOURCE=.../swirl.####.vdb from `vdbturb sim`), CHECK_ARGS go to check_farm.py.
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=${BIN:-$ROOT/build/tools/vdbturb}
DATA=${DATA:-$ROOT/../shared/data}
WORK=${WORK:-/tmp/vdbturb-farm-quality}
N=${1:-2}; P=${2:-8}; O=${3:-10}
T=${TARGET:-$DATA/blender-plume2-32/fluid_data_####.vdb}
S=${SOURCE:-$DATA/blender-plume2-128/fluid_data_####.vdb}
R="$WORK/n${N}_p${P}_o${O}"
mkdir -p "$WORK"
[ -f "$WORK/seq/done" ] || { "$BIN" transfer --target "$T" --source "$S" --out "$WORK/seq/turb.####.vdb" --threads 2 \
  --target-no-crop --source-no-crop -q && touch "$WORK/seq/done"; }
[ -f "$WORK/seq.measure.json" ] || "$BIN" measure --output "$WORK/seq/turb.####.vdb" --target "$T" --source "$S" \
  --no-spectra --no-structure -q > "$WORK/seq.measure.json"
rm -rf "$R"
"$BIN" farm plan --dir "$R/farm" --target "$T" --source "$S" --out "$R/joined/turb.####.vdb" --chunks "$N" --preroll "$P" \
  --overlap "$O" --cpus 2
k=0
while [ "$k" -lt "$N" ]; do
  SLURM_ARRAY_TASK_ID=$k sh "$R/farm/chunks.sbatch" 2>> "$R/farm/logs/chunk_$k.log"
  k=$((k + 1))
done
sh "$R/farm/join.sbatch" 2>> "$R/farm/logs/join.log"
"$BIN" measure --output "$R/joined/turb.####.vdb" --target "$T" --source "$S" --no-spectra --no-structure -q > "$R/joined.measure.json"
grep "blend" "$R/farm/logs/join.log" || true
# shellcheck disable=SC2086
python3 "$ROOT/tests/farm/check_farm.py" "$R/farm/plan.json" "$WORK/seq" "$R/joined" "$WORK/seq.measure.json" \
  "$R/joined.measure.json" ${CHECK_ARGS:-}
