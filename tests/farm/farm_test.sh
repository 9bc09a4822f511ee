#!/bin/sh
# Time chunks end to end on a small built-in pair (plume 16x16x24 -> swirl 64x64x96, f = 4, 12 frames, 3 chunks,
# pre-roll 2, overlap 2), checked against a sequential run of the same transfer by check_farm.py; and the same
# transfer as 2 space tiles (halo 4), checked at the tile border by check_tiles.py.
#   farm_test.sh local VDBTURB WORK   runs each array task's script by hand (no Slurm needed)
#   farm_test.sh slurm VDBTURB WORK   a real one-node Slurm cluster (munged, slurmctld, slurmd as root, config in
#                                     WORK): farm submit, one task killed with SIGKILL in the middle of a frame write
#                                     and requeued by its script, then the join. Skipped (exit 77) without slurm-wlm.
set -eu
MODE=$1
BIN=$(readlink -f "$2")
W=$3
HERE=$(cd "$(dirname "$0")" && pwd)
FRAMES=12
# Two VDB files hold the same grids and metadata when all their bytes but the header's random UUID (OpenVDB writes
# a fresh one into every file: 36 characters from byte 22) agree.
same_content() {
  [ "$(head -c 21 "$1" | od -An -tx1)" = "$(head -c 21 "$2" | od -An -tx1)" ] && tail -c +58 "$1" > "$W/.a" &&
    tail -c +58 "$2" > "$W/.b" && cmp -s "$W/.a" "$W/.b"
}
. "$HERE/slurm_cluster.sh"
[ "$MODE" != slurm ] || require_cluster
command -v python3 >/dev/null || { echo "SKIP: python3 is needed to read measure's JSON"; exit 77; }
rm -rf "$W"
mkdir -p "$W"
W=$(readlink -f "$W")

"$BIN" sim plume --res 16x16x24 --frames $FRAMES --seed 1 --out "$W/t/plume.####.vdb" -q
"$BIN" sim swirl --res 64x64x96 --frames $FRAMES --seed 2 --out "$W/s/swirl.####.vdb" -q
"$BIN" transfer --target "$W/t/plume.####.vdb" --source "$W/s/swirl.####.vdb" --out "$W/seq/turb.####.vdb" -q --threads 2 --target-no-crop --source-no-crop
"$BIN" farm plan --dir "$W/farm" --target "$W/t/plume.####.vdb" --source "$W/s/swirl.####.vdb" \
  --out "$W/joined/turb.####.vdb" --chunks 3 --preroll 2 --overlap 2 --cpus 1 --vdbturb "$W/vdbturb-wrapper" -q
"$BIN" farm plan --dir "$W/tiles" --target "$W/t/plume.####.vdb" --source "$W/s/swirl.####.vdb" \
  --out "$W/tjoined/turb.####.vdb" --tiles 2 --halo 4 --cpus 1 --vdbturb "$W/vdbturb-wrapper" -q

# The tasks run the binary through a wrapper: in the Slurm test it makes chunk 1's and tile 1's first attempt SIGKILL itself in
# the middle of its 4th frame write (the IO layer's VDBTURB_TEST_KILL_IN_WRITE hook), leaving a partial temporary
# file, as a node dying or kill -9 would.
cat > "$W/vdbturb-wrapper" <<WRAP
#!/bin/sh
if [ "$MODE" = slurm ] && [ "\${SLURM_ARRAY_TASK_ID:-}" = 1 ] && [ "\${SLURM_RESTART_COUNT:-0}" = 0 ]; then
  export VDBTURB_TEST_KILL_IN_WRITE=4
fi
exec "$BIN" "\$@"
WRAP
chmod +x "$W/vdbturb-wrapper"

if [ "$MODE" = local ]; then
  # A join before the chunks ran must refuse, naming the chunk to rerun, and write nothing.
  if "$BIN" farm join --dir "$W/farm" -q 2>"$W/early_join.err"; then echo "FAIL: join of missing chunks succeeded"; exit 1; fi
  grep -q "chunk 0 is not complete" "$W/early_join.err" || { echo "FAIL: early join said:"; cat "$W/early_join.err"; exit 1; }
  [ ! -d "$W/joined" ] || { echo "FAIL: early join wrote output"; exit 1; }
  for k in 0 1 2; do SLURM_ARRAY_TASK_ID=$k sh "$W/farm/chunks.sbatch" 2>>"$W/farm/logs/chunk_$k.log"; done
  sh "$W/farm/join.sbatch" 2>>"$W/farm/logs/join.log"
  for k in 0 1; do SLURM_ARRAY_TASK_ID=$k sh "$W/tiles/tiles.sbatch" 2>>"$W/tiles/logs/tile_$k.log"; done
  sh "$W/tiles/join.sbatch" 2>>"$W/tiles/logs/join.log"
else
  start_cluster "$W/cluster"
  "$BIN" farm submit --dir "$W/farm" --json > "$W/submitted.json"
  "$BIN" farm submit --dir "$W/tiles" --json > "$W/tiles_submitted.json"
  TJOIN=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['join_job'])" "$W/tiles_submitted.json")
  JOIN=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['join_job'])" "$W/submitted.json")
  i=0
  while squeue -h -j "$JOIN,$TJOIN" 2>/dev/null | grep -q .; do
    i=$((i + 1))
    if [ $i -gt 600 ]; then echo "FAIL: the joins did not finish in 5 minutes"; squeue; exit 1; fi
    if squeue -h -o "%r" -j "$JOIN,$TJOIN" 2>/dev/null | grep -q DependencyNeverSatisfied; then
      echo "FAIL: a task failed for good, so a join can never start"; squeue; tail -n 5 "$W"/farm/logs/*.log "$W"/tiles/logs/*.log
      exit 1
    fi
    # Slurm holds a requeued job about two minutes before it is eligible again; an operator may release it sooner.
    release_requeued "$W/released"
    sleep 0.5
  done
  tstate=$(scontrol -o show job "$TJOIN" | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p')
  echo "tile join job $TJOIN: $tstate"
  [ "$tstate" = COMPLETED ] || { echo "FAIL: tile join $tstate"; cat "$W/tiles/logs/"*.log; exit 1; }
  state=$(scontrol -o show job "$JOIN" | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p')
  echo "join job $JOIN: $state"
  [ "$state" = COMPLETED ] || { echo "FAIL: join $state"; cat "$W/farm/logs/"*.log; exit 1; }
  # The killed task: its script saw the kill, requeued it, and the second attempt resumed after the last whole frame.
  grep -q "farm: chunk 1 exit 137" "$W/farm/logs/chunk_1.log" || { echo "FAIL: chunk 1 was not killed"; cat "$W/farm/logs/chunk_1.log"; exit 1; }
  grep -q "farm: chunk 1 start (restart 1)" "$W/farm/logs/chunk_1.log" || { echo "FAIL: chunk 1 was not requeued"; cat "$W/farm/logs/chunk_1.log"; exit 1; }
  grep "resume: continuing after frame" "$W/farm/logs/chunk_1.log" || { echo "FAIL: chunk 1 did not resume"; cat "$W/farm/logs/chunk_1.log"; exit 1; }
  # Whole and correct: the resumed chunk's frames are bit-identical to the same chunk run without a kill.
  sed -n 's/^  1) set -- \(.*\) ;;$/\1/p' "$W/farm/chunks.sbatch" | sed "s|$W/farm/chunks/001/|$W/ref1/|" > "$W/ref1.sh"
  sh -c "$(cat "$W/ref1.sh") -q"
  n=0
  for f in "$W/ref1/"*.vdb; do
    same_content "$f" "$W/farm/chunks/001/$(basename "$f")" || { echo "FAIL: $(basename "$f") differs from an uninterrupted chunk 1"; exit 1; }
    n=$((n + 1))
  done
  echo "chunk 1 after kill -9 + requeue: $n frames bit-identical (all but the file UUID) to an uninterrupted run"
  [ "$(ls "$W/farm/chunks/001/" | grep -c tmp || true)" = 0 ] || { echo "FAIL: temporary files left"; ls "$W/farm/chunks/001/"; exit 1; }
  # Tile 1 (array index 1 too) went through the same kill and requeue.
  grep -q "farm: tile 1 exit 137" "$W/tiles/logs/tile_1.log" || { echo "FAIL: tile 1 was not killed"; cat "$W/tiles/logs/tile_1.log"; exit 1; }
  grep "resume: continuing after frame" "$W/tiles/logs/tile_1.log" || { echo "FAIL: tile 1 did not resume"; cat "$W/tiles/logs/tile_1.log"; exit 1; }
fi

"$BIN" measure --output "$W/seq/turb.####.vdb" --target "$W/t/plume.####.vdb" --source "$W/s/swirl.####.vdb" \
  --no-spectra --no-structure -q > "$W/seq.measure.json"
"$BIN" measure --output "$W/joined/turb.####.vdb" --target "$W/t/plume.####.vdb" --source "$W/s/swirl.####.vdb" \
  --no-spectra --no-structure -q > "$W/joined.measure.json"
python3 "$HERE/check_farm.py" "$W/farm/plan.json" "$W/seq" "$W/joined" "$W/seq.measure.json" "$W/joined.measure.json" ${CHECK_ARGS:-}

# Space tiles: the untiled run measured at the tiles' border, against the joined tiles.
grep -q '"kind": "space_tiles"' "$W/tiles/plan.json" || { echo "FAIL: the tile plan.json has no space_tiles kind"; exit 1; }
BORDERS=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['tiles']['borders'])" "$W/tiles/plan.json")
"$BIN" measure --output "$W/seq/turb.####.vdb" --target "$W/t/plume.####.vdb" --source "$W/s/swirl.####.vdb" \
  --no-spectra --no-structure --tile-borders "$BORDERS" -q > "$W/seq.tiles.measure.json"
"$BIN" measure --output "$W/tjoined/turb.####.vdb" --target "$W/t/plume.####.vdb" --source "$W/s/swirl.####.vdb" \
  --no-spectra --no-structure -q > "$W/tjoined.measure.json"
python3 "$HERE/check_tiles.py" "$W/tiles/plan.json" "$W/seq.tiles.measure.json" "$W/tjoined.measure.json"
