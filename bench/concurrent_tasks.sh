#!/bin/sh
# Four transfers of one shot at once into one folder (issue 49, item 3): docs/reliability.md quotes the table. Not a
# test (FarmNode.FourTasksOfOneShotInOneFolder... in test_cli is the seconds-long one): it takes minutes.
#
#   bench/concurrent_tasks.sh [--vdbturb PATH] [--work DIR] [--seed S] [--preroll P]
#
# The shot: blender-plume2-32 -> blender-plume2-128 (../shared/data), frames 1-30, as four tasks the way a farm
# splits it: 1-8, 9-15, 16-23 and 24-30, the later three with P (2) pre-roll frames (computed, not written).
# 1. Each task alone, one after another, into a folder of its own (2 threads; transfer's result is the same at any
#    thread count). A transfer carries its detail from frame to frame, so these are what each task's frames must be.
# 2. The four at once on this machine's cores (1 thread each), all writing into one folder. Task 2 is killed with
#    SIGKILL after a seeded random delay (printed; 1.5-3 times its time alone) and run again with --resume while the
#    others still run, as a farm requeues a task.
# Checks: each frame written exactly once (one JSON line across all runs), bit-identical (all but the header's random
# UUID) to its task run alone, and the folder holds the 30 frames and each task's resume states, no temporary file,
# no lock file. Prints one row per task and exits 1 when a check fails. Needs POSIX sh, awk and coreutils.
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
DATA="$(cd "$ROOT/.." && pwd)/shared/data"
VDBTURB="$ROOT/build/tools/vdbturb"
WORK="${TMPDIR:-/tmp}/vdbturb-concurrent-tasks"
SEED=1
PREROLL=2
while [ $# -gt 0 ]; do
    case "$1" in
    --vdbturb) VDBTURB=$2; shift 2 ;;
    --work) WORK=$2; shift 2 ;;
    --seed) SEED=$2; shift 2 ;;
    --preroll) PREROLL=$2; shift 2 ;;
    -h|--help) sed -n "2,17p" "$0" | sed "s/^# \{0,1\}//"; exit 0 ;;
    *) echo "usage: $0 [--vdbturb PATH] [--work DIR] [--seed S] [--preroll P]" >&2; exit 2 ;;
    esac
done
VDBTURB=$(readlink -f "$VDBTURB")
rm -rf "$WORK"
mkdir -p "$WORK/logs"
log() { printf 'concurrent-tasks: %s\n' "$*" >&2; }
. "$ROOT/bench/timing_compare.sh" # now, since, same_content
TASKS="1-8 9-15 16-23 24-30"
task_args() { # $1 = frames: the --frames and --preroll of the task
    case "$1" in 1-*) echo "--frames $1" ;; *) echo "--frames $1 --preroll $PREROLL" ;; esac
}
set -- transfer --target "$DATA/blender-plume2-32/fluid_data_####.vdb" \
    --source "$DATA/blender-plume2-128/fluid_data_####.vdb"
log "vdbturb $VDBTURB, tasks $TASKS (pre-roll $PREROLL), seed $SEED, work $WORK"

k=0
for t in $TASKS; do
    k=$((k + 1))
    t0=$(now)
    # shellcheck disable=SC2046
    "$VDBTURB" "$@" $(task_args "$t") --threads 2 --out "$WORK/alone$k/o.####.vdb" -q </dev/null
    eval "ALONE_$k=$(since "$t0")"
done
ALONE_ALL=$(awk -v a="$ALONE_1" -v b="$ALONE_2" -v c="$ALONE_3" -v d="$ALONE_4" 'BEGIN { printf "%.1f", a + b + c + d }')
log "alone, one after another: $ALONE_ALL s"

# Four tasks on this machine's cores take about 3-4 times as long as one alone with all of them: the kill lands after
# 1.5-3 times task 2's time alone, past its pre-roll and before its end.
KILL_AT=$(awk -v seed="$SEED" -v t="$ALONE_2" 'BEGIN { srand(seed); printf "%.2f", t * (1.5 + 1.5 * rand()) }')
log "task 2 is killed after $KILL_AT s (seed $SEED) and resumed"
t_all=$(now)
k=0
for t in $TASKS; do
    k=$((k + 1))
    (
        t0=$(now)
        # shellcheck disable=SC2046
        "$VDBTURB" "$@" $(task_args "$t") --threads 1 --json --out "$WORK/one/o.####.vdb" </dev/null \
            > "$WORK/logs/task$k.log" 2>&1 &
        pid=$!
        rc=0
        if [ "$k" = 2 ]; then
            sleep "$KILL_AT"
            if kill -9 "$pid" 2>/dev/null; then
                wait "$pid" || true
                echo "killed after $KILL_AT s with $(grep -c '^frame [0-9]* (' "$WORK/logs/task$k.log" || true) frames written" \
                    > "$WORK/logs/task$k.kill"
                # shellcheck disable=SC2046
                "$VDBTURB" "$@" $(task_args "$t") --threads 1 --json --resume --out "$WORK/one/o.####.vdb" \
                    </dev/null > "$WORK/logs/task$k.resume.log" 2>&1 || rc=$?
            else
                wait "$pid" || rc=$?
            fi
        else
            wait "$pid" || rc=$?
        fi
        echo "$rc $(since "$t0")" > "$WORK/logs/task$k.rc"
    ) &
done
wait
ALL_S=$(since "$t_all")

fails=0
printf '%-5s %-20s %-8s %-10s %-5s %-8s %-10s %s\n' task frames alone_s at_once_s "exit" written identical note
k=0
for t in $TASKS; do
    k=$((k + 1))
    read -r rc secs < "$WORK/logs/task$k.rc"
    first=${t%-*} last=${t#*-}
    written=0 same=0 n=0
    f=$first
    while [ "$f" -le "$last" ]; do
        name=$(printf 'o.%04d.vdb' "$f")
        n=$((n + 1))
        c=$(cat "$WORK/logs/task$k"*.log | grep -c "\"out\":\"$WORK/one/$name\"" || true)
        [ "$c" = 1 ] && written=$((written + 1))
        [ "$c" = 1 ] || log "$name: $c JSON lines (written $c times)"
        if [ -f "$WORK/one/$name" ] && same_content "$WORK/one/$name" "$WORK/alone$k/$name"; then same=$((same + 1)); else
            log "$name differs from task $k run alone"
        fi
        f=$((f + 1))
    done
    note=
    [ -f "$WORK/logs/task$k.kill" ] && note="$(cat "$WORK/logs/task$k.kill"), $(sed -n 's/^resume: \(continuing after frame .*\)/\1/p' "$WORK/logs/task$k.resume.log")"
    grep -q "cannot be used" "$WORK/logs/task$k"*.log && { note="$note APPROXIMATE RESUME"; fails=$((fails + 1)); }
    eval "alone=\$ALONE_$k"
    printf '%-5s %-20s %-8s %-10s %-5s %-8s %-10s %s\n' "$k" "$(task_args "$t" | sed 's/--frames //')" "$alone" \
        "$secs" "$rc" "$written/$n" "$same/$n" "$note"
    [ "$rc" = 0 ] && [ "$written" = "$n" ] && [ "$same" = "$n" ] || fails=$((fails + 1))
done
others=$(ls -A "$WORK/one" | grep -v '^o\.[0-9]\{4\}\.vdb$' | grep -v '^o\.resume-state-\([0-9]*-\)\{0,1\}\(odd\|even\)\.vdb$' || true)
frames=$(ls "$WORK/one" | grep -c '^o\.[0-9]\{4\}\.vdb$' || true)
echo
echo "alone, one after another: $ALONE_ALL s; the four at once: $ALL_S s; $frames frames in the folder"
echo "left beside them (temporary files, the lock, anything else): ${others:-nothing}"
[ -z "$others" ] && [ "$frames" = 30 ] || fails=$((fails + 1))
if [ "$fails" != 0 ]; then echo "FAIL"; exit 1; fi
echo "PASS"
