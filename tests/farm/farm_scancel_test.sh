#!/bin/sh
# Farm tasks stopped by Slurm itself (issue 49, item 2), on a real one-node Slurm cluster (slurm_cluster.sh): the
# built-in pair of farm_test.sh (plume 16x16x24 -> swirl 64x64x96, 12 frames, 3 chunks, pre-roll 2, overlap 2), each
# chunk's task let write two frames, then
#   chunk 2: `scontrol requeue` while it runs: Slurm stops it (SIGTERM) and requeues it, as preemption with
#            PreemptMode=REQUEUE does; it runs again by itself (after the hold Slurm puts on a requeued job, which the
#            test releases 5 s later);
#   chunk 1: `scancel`: Slurm sends SIGTERM to the task's script and vdbturb alike; the task ends CANCELLED and stays
#            so (a cancel sticks: the script does not requeue it), and the join's afterok can then never be
#            satisfied, also not after `scontrol requeue` (Slurm keeps the array's failure). The operator reruns it
#            with docs/farm.md's recipe: scancel the join, `sbatch --array=1 chunks.sbatch`, a new join after it.
# The script's shell usually dies of Slurm's SIGTERM before vdbturb ends; the test makes it outlive vdbturb (trap ''
# TERM in chunks.sbatch), the worst case of that race (seen once in four plain scancels of a short-lived child):
# the script then sees vdbturb's exit 130 and must not requeue a job that Slurm is stopping (COMPLETING).
# Each rerun task runs its chunk's command again (`transfer ... --resume`) and must continue after its last whole
# frame; its frames must then be bit-identical (all but the file UUID) to the same chunk run without a stop, its
# folder must hold no temporary or lock file, and the new join must complete.
#   farm_scancel_test.sh VDBTURB WORK    skipped (exit 77) without slurm-wlm, munge or root
set -eu
BIN=$(readlink -f "$1")
W=$2
HERE=$(cd "$(dirname "$0")" && pwd)
FRAMES=12
. "$HERE/slurm_cluster.sh"
require_cluster
command -v python3 >/dev/null || { echo "SKIP: python3 is needed to read farm submit's JSON"; exit 77; }
same_content() {
  [ "$(head -c 21 "$1" | od -An -tx1)" = "$(head -c 21 "$2" | od -An -tx1)" ] && tail -c +58 "$1" > "$W/.a" &&
    tail -c +58 "$2" > "$W/.b" && cmp -s "$W/.a" "$W/.b"
}
state_of() { scontrol -o show job "$1" | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p'; }
frames_in() { ls "$W/farm/chunks/$1/" 2>/dev/null | grep -c '^turb\.[0-9]*\.vdb$' || true; }
rm -rf "$W"
mkdir -p "$W"
W=$(readlink -f "$W")

"$BIN" sim plume --res 16x16x24 --frames $FRAMES --seed 1 --out "$W/t/plume.####.vdb" -q
"$BIN" sim swirl --res 64x64x96 --frames $FRAMES --seed 2 --out "$W/s/swirl.####.vdb" -q
"$BIN" farm plan --dir "$W/farm" --target "$W/t/plume.####.vdb" --source "$W/s/swirl.####.vdb" \
  --out "$W/joined/turb.####.vdb" --chunks 3 --preroll 2 --overlap 2 --cpus 1 --vdbturb "$BIN" -q

# After the #SBATCH lines (sbatch reads none after the first command).
sed -i '/^case "\$SLURM_ARRAY_TASK_ID" in$/i trap "" TERM # farm_scancel_test.sh: this shell outlives vdbturb' \
  "$W/farm/chunks.sbatch"
grep -q '^trap "" TERM' "$W/farm/chunks.sbatch" || { echo "FAIL: cannot add the trap to chunks.sbatch"; exit 1; }

start_cluster "$W/cluster"
"$BIN" farm submit --dir "$W/farm" --json > "$W/submitted.json"
A=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['chunks_job'])" "$W/submitted.json")
JOIN=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['join_job'])" "$W/submitted.json")

# Chunks 1 (7 frames) and 2 (8 frames) each let write two frames: stopped in the middle of their run.
for k in 1 2; do
  i=0
  until [ "$(frames_in 00$k)" -ge 2 ]; do
    i=$((i + 1))
    if [ $i -gt 1200 ]; then echo "FAIL: chunk $k wrote no two frames in 4 minutes"; squeue; cat "$W/farm/logs/chunk_$k.log"; exit 1; fi
    sleep 0.2
  done
done
[ "$(state_of "${A}_1")" = RUNNING ] && [ "$(state_of "${A}_2")" = RUNNING ] ||
  { echo "FAIL: chunks 1 and 2 should still run"; squeue -t all; exit 1; }
scontrol requeue "${A}_2"
scancel "${A}_1"
echo "scontrol requeue ${A}_2 at $(frames_in 002) frames, scancel ${A}_1 at $(frames_in 001) frames"
# Chunk 2 runs again and chunk 0 ends; chunk 1 stays cancelled and the join can never start.
i=0
until [ "$(state_of "${A}_2")" = COMPLETED ] && [ "$(state_of "${A}_0")" = COMPLETED ]; do
  i=$((i + 1))
  if [ $i -gt 600 ]; then echo "FAIL: chunks 0 and 2 did not complete in 5 minutes"; squeue -t all; exit 1; fi
  case "$(state_of "${A}_2")$(state_of "${A}_0")" in *FAILED*|*CANCELLED*)
    echo "FAIL: chunk 0 or 2 failed"; squeue -t all; tail -n 5 "$W"/farm/logs/*.log; exit 1 ;;
  esac
  release_requeued "$W/released"
  sleep 0.5
done
[ "$(state_of "${A}_1")" = CANCELLED ] || { echo "FAIL: the cancelled ${A}_1 became $(state_of "${A}_1")"; exit 1; }
i=0
until squeue -h -o "%r" -j "$JOIN" | grep -q DependencyNeverSatisfied; do
  i=$((i + 1))
  if [ $i -gt 60 ]; then echo "FAIL: the join waits on a cancelled task: $(squeue -h -o '%T %r' -j "$JOIN")"; exit 1; fi
  sleep 0.5
done
echo "chunk 1 CANCELLED with $(frames_in 001) whole frames; join $JOIN: DependencyNeverSatisfied; rerunning chunk 1"
scancel "$JOIN"
B=$(sbatch --parsable --array=1 "$W/farm/chunks.sbatch")
JOIN=$(sbatch --parsable --dependency=afterok:"$B" "$W/farm/join.sbatch")
i=0
while squeue -h -j "$JOIN" 2>/dev/null | grep -q .; do
  i=$((i + 1))
  if [ $i -gt 600 ]; then echo "FAIL: the new join did not finish in 5 minutes"; squeue; exit 1; fi
  if squeue -h -o "%r" -j "$JOIN" 2>/dev/null | grep -q DependencyNeverSatisfied; then
    echo "FAIL: the rerun chunk 1 failed, so the join can never start"; squeue -t all; tail -n 5 "$W"/farm/logs/*.log
    exit 1
  fi
  sleep 0.5
done
state=$(state_of "$JOIN")
echo "join job $JOIN: $state"
[ "$state" = COMPLETED ] || { echo "FAIL: join $state"; cat "$W/farm/logs/"*.log; exit 1; }

for k in 1 2; do
  L="$W/farm/logs/chunk_$k.log"
  [ "$(grep -c "farm: chunk $k start" "$L")" = 2 ] || { echo "FAIL: chunk $k was not run again"; cat "$L"; exit 1; }
  grep "resume: continuing after frame" "$L" || { echo "FAIL: chunk $k did not resume"; cat "$L"; exit 1; }
  # The script saw the stop (SIGTERM: vdbturb's exit 130) and left the job to Slurm.
  grep -q "farm: chunk $k exit 130" "$L" && grep -q "farm: chunk $k not requeued by its script: the job is COMPLETING" "$L" ||
    { echo "FAIL: chunk $k's script did not leave the stopped job to Slurm"; cat "$L"; exit 1; }
  if grep -q "farm: chunk $k requeued" "$L"; then echo "FAIL: chunk $k's script requeued a job Slurm stopped"; cat "$L"; exit 1; fi
  # Whole and correct: the resumed chunk's frames are bit-identical to the same chunk run without a stop.
  sed -n "s/^  $k) set -- \\(.*\\) ;;\$/\\1/p" "$W/farm/chunks.sbatch" | sed "s|$W/farm/chunks/00$k/|$W/ref$k/|" > "$W/ref$k.sh"
  sh -c "$(cat "$W/ref$k.sh") -q"
  n=0
  for f in "$W/ref$k/"turb.[0-9]*.vdb; do
    same_content "$f" "$W/farm/chunks/00$k/$(basename "$f")" ||
      { echo "FAIL: chunk $k: $(basename "$f") differs from an uninterrupted run"; exit 1; }
    n=$((n + 1))
  done
  [ "$n" = "$(frames_in 00$k)" ] || { echo "FAIL: chunk $k holds $(frames_in 00$k) frames, the uninterrupted run $n"; exit 1; }
  left=$(ls -A "$W/farm/chunks/00$k/" | grep '^\.' || true)
  [ -z "$left" ] || { echo "FAIL: chunk $k: left behind: $left"; exit 1; }
  echo "chunk $k, $([ $k = 1 ] && echo 'scancel and sbatch --array=1' || echo 'scontrol requeue'): $n frames bit-identical (all but the file UUID) to an uninterrupted run"
done
grep -q "CANCELLED AT .* DUE TO JOB REQUEUE" "$W/farm/logs/chunk_2.log" || { echo "FAIL: chunk 2 was not stopped by the requeue"; exit 1; }
grep -q "farm: chunk 2 start (restart 1)" "$W/farm/logs/chunk_2.log" || { echo "FAIL: chunk 2 was not requeued"; exit 1; }
echo "PASS"
