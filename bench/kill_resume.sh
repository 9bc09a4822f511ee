#!/bin/sh
# kill -9 and --resume on a 30-frame transfer (issue 49, item 2): docs/reliability.md quotes the table. Not a test
# (tests/cli/test_faults.cc has the seconds-long ones): it takes minutes.
#
#   bench/kill_resume.sh [--vdbturb PATH] [--work DIR] [--kills N] [--seed S] [--threads T] [--frames LIST]
#
# 1. An uninterrupted run: blender-plume2-32 -> blender-plume2-128 (../shared/data), frames 1-30, T threads (2),
#    timed (R seconds).
# 2. The same run into another folder, killed with SIGKILL again and again, each time followed by `--resume`:
#    first three kills at points chosen by the CLI's test hooks at seeded random frames: in the middle of a frame's
#    write (VDBTURB_TEST_KILL_IN_WRITE), in the middle of the seam solve and between the frame's resume state and the
#    frame (VDBTURB_TEST_KILL_AT); then N (8) kills after seeded random delays, uniform in [0.5, R/N] seconds from
#    the start of each attempt (printed; where they land depends on the machine's speed). Every attempt runs with -v,
#    so its log's last "frame F: STEP" line says where the kill landed. After each kill: every frame on disk must be
#    the uninterrupted run's, bit for bit (less the header's random UUID), and only temporary files (.NAME.tmpPID_N)
#    and the lock file may lie beside them.
# 3. A last --resume to the end; then every frame is compared with the uninterrupted run's (bytes and
#    `info --checksum` of every grid), the folder must hold no temporary or lock file, and no resume may have
#    continued approximately ("cannot be used" in a log).
# Prints one row per kill and a summary; exits 1 when a check fails. Needs POSIX sh, awk and coreutils.
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
DATA="$(cd "$ROOT/.." && pwd)/shared/data"
VDBTURB="$ROOT/build/tools/vdbturb"
WORK="${TMPDIR:-/tmp}/vdbturb-kill-resume"
KILLS=8
SEED=1
THREADS=2
FRAMES=1-30
while [ $# -gt 0 ]; do
    case "$1" in
    --vdbturb) VDBTURB=$2; shift 2 ;;
    --work) WORK=$2; shift 2 ;;
    --kills) KILLS=$2; shift 2 ;;
    --seed) SEED=$2; shift 2 ;;
    --threads) THREADS=$2; shift 2 ;;
    --frames) FRAMES=$2; shift 2 ;;
    -h|--help) sed -n "2,24p" "$0" | sed "s/^# \{0,1\}//"; exit 0 ;;
    *) echo "usage: $0 [--vdbturb PATH] [--work DIR] [--kills N] [--seed S] [--threads T] [--frames LIST]" >&2; exit 2 ;;
    esac
done
VDBTURB=$(readlink -f "$VDBTURB")
rm -rf "$WORK"
mkdir -p "$WORK/logs"
log() { printf 'kill-resume: %s\n' "$*" >&2; }
. "$ROOT/bench/timing_compare.sh" # now, since, same_content
# The frames in folder $1 that are not the reference's, and the files beside them that are neither frames, state
# files, temporary files nor the lock: "bad=N other=M temps=K frames=F".
check_folder() {
    bad=0 other=0 temps=0 frames=0
    for f in "$1"/* "$1"/.[!.]*; do
        [ -e "$f" ] || continue
        b=$(basename "$f")
        case "$b" in
        o.[0-9][0-9][0-9][0-9].vdb)
            frames=$((frames + 1))
            if ! same_content "$f" "$WORK/ref/$b"; then bad=$((bad + 1)); log "NOT the uninterrupted run's: $f"; fi ;;
        o.resume-state-*.vdb) ;;
        .o.*.vdb.tmp*) temps=$((temps + 1)) ;;
        .o.####.vdb.lock) ;;
        *) other=$((other + 1)); log "unexpected file: $f" ;;
        esac
    done
    echo "bad=$bad other=$other temps=$temps frames=$frames"
}
# Where the kill landed: the last "frame F: STEP" line of the attempt's log (-v), or the last line.
landed() {
    l=$(grep -E '^ *frame -?[0-9]+: [a-z]+( [a-z]+)?$' "$1" | tail -1 | sed 's/^ *//')
    [ -n "$l" ] || l="startup ($(grep -v '^Killed' "$1" | tail -1 | cut -c1-40))"
    echo "$l"
}

log "vdbturb $VDBTURB, frames $FRAMES, $THREADS threads, $KILLS timed kills, seed $SEED, work $WORK"
# The transfer's arguments, less --out.
set -- transfer --target "$DATA/blender-plume2-32/fluid_data_####.vdb" \
    --source "$DATA/blender-plume2-128/fluid_data_####.vdb" --frames "$FRAMES" --threads "$THREADS"
t0=$(now)
"$VDBTURB" "$@" --out "$WORK/ref/o.####.vdb" -q </dev/null
REF_S=$(since "$t0")
NFRAMES=$(ls "$WORK/ref" | grep -c '^o\.[0-9]*\.vdb$')
log "uninterrupted: $NFRAMES frames in $REF_S s"

# The kills: three hooked ones at seeded random frames in the first half, each later than the one before (a resume
# starts after the last whole frame), then the timed ones. The first attempt starts at frame 1, and every frame of
# this Blender target writes its resume state and then itself: write 2m is the m-th frame's.
PLAN=$(awk -v seed="$SEED" -v n="$KILLS" -v r="$REF_S" -v nf="$NFRAMES" -v first="${FRAMES%%-*}" 'BEGIN {
    srand(seed)
    h = int(nf / 6); if (h < 1) h = 1
    m1 = 2 + int(rand() * h); m2 = m1 + 1 + int(rand() * h); m3 = m2 + 1 + int(rand() * h)
    printf "hook VDBTURB_TEST_KILL_IN_WRITE=%d\n", 2 * m1
    printf "hook VDBTURB_TEST_KILL_AT=seams:%d\n", first + m2 - 1
    printf "hook VDBTURB_TEST_KILL_AT=after-state:%d\n", first + m3 - 1
    for (i = 0; i < n; ++i) printf "delay %.2f\n", 0.5 + rand() * (r / n - 0.5)
}')
log "kill plan (seed $SEED):"
echo "$PLAN" | sed 's/^/  /' >&2

OUT="$WORK/k/o.####.vdb"
set -- "$@" --out "$OUT"
printf '%-4s %-31s %-8s %-24s %-6s %-5s %-6s %s\n' kill how status "landed in (-v's last)" frames temps wrong "resumed after"
k=0 fails=0 finished=0 t_all=$(now)
echo "$PLAN" > "$WORK/plan"
while read -r kind what; do
    k=$((k + 1))
    L="$WORK/logs/attempt$k.log"
    if [ "$kind" = hook ]; then
        env "$what" "$VDBTURB" "$@" --resume -v </dev/null > "$L" 2>&1 && rc=0 || rc=$?
    else
        "$VDBTURB" "$@" --resume -v </dev/null > "$L" 2>&1 &
        pid=$!
        sleep "$what"
        kill -9 "$pid" 2>/dev/null || true
        wait "$pid" && rc=0 || rc=$?
    fi
    resumed=$(sed -n 's/^resume: continuing after frame \(.*\)/\1/p' "$L" | tail -1)
    [ -n "$resumed" ] || resumed=-
    c=$(check_folder "$WORK/k")
    eval "$c"
    st=$rc
    [ "$rc" = 137 ] && st=SIGKILL
    [ "$rc" = 0 ] && finished=1
    case "$what" in
    VDBTURB_TEST_KILL_IN_WRITE=*) how="hook: in write ${what#*=} (its frame's)" ;;
    VDBTURB_TEST_KILL_AT=*) how="hook: at ${what#*=}" ;;
    *) how="after $what s" ;;
    esac
    printf '%-4s %-31s %-8s %-24s %-6s %-5s %-6s %s\n' "$k" "$how" "$st" "$(landed "$L")" "$frames" "$temps" \
        "$bad" "$resumed"
    if [ "$bad" != 0 ] || [ "$other" != 0 ]; then fails=$((fails + 1)); fi
    case "$rc" in 0|137) ;; *) log "attempt $k exited $rc:"; tail -5 "$L" >&2; fails=$((fails + 1)) ;; esac
    [ "$finished" = 1 ] && break
done < "$WORK/plan"
if [ "$finished" = 0 ]; then
    k=$((k + 1))
    L="$WORK/logs/attempt$k.log"
    "$VDBTURB" "$@" --resume -v </dev/null > "$L" 2>&1 && rc=0 || rc=$?
    resumed=$(sed -n 's/^resume: continuing after frame \(.*\)/\1/p' "$L" | tail -1)
    eval "$(check_folder "$WORK/k")"
    printf '%-4s %-31s %-8s %-24s %-6s %-5s %-6s %s\n' "$k" "none: the last --resume" "$rc" "(ran to the end)" "$frames" "$temps" \
        "$bad" "${resumed:--}"
    [ "$rc" = 0 ] || { log "the last resume exited $rc"; tail -5 "$L" >&2; fails=$((fails + 1)); }
fi
TOTAL_S=$(since "$t_all")

# The end: every frame the uninterrupted run's, bit for bit and by info's checksums; nothing else left.
eval "$(check_folder "$WORK/k")"
lock=0
[ -e "$WORK/k/.o.####.vdb.lock" ] && lock=1
sums() { "$VDBTURB" info --checksum "$1" 2>/dev/null | grep -E '^(frame -?[0-9]+:|  [a-z]+ +[a-z0-9]+ +[0-9]+ +[0-9a-f]{16} )' | sed 's/^\(frame -\{0,1\}[0-9]*\):.*/\1/'; }
sums "$WORK/ref/o.####.vdb" > "$WORK/ref.sums"
sums "$OUT" > "$WORK/k.sums"
if cmp -s "$WORK/ref.sums" "$WORK/k.sums" && [ -s "$WORK/ref.sums" ]; then checks=equal; else checks=DIFFER; fi
approx=$(cat "$WORK"/logs/*.log | grep -c "cannot be used" || true)
echo
echo "uninterrupted run: $NFRAMES frames, $REF_S s; killed run: $((k - 1)) kills + resumes, $TOTAL_S s in all"
echo "frames: $frames of $NFRAMES on disk, $bad not bit-identical to the uninterrupted run's; info --checksum of every grid: $checks"
echo "left beside them: $temps temporary files, $lock lock file, $other other files; approximate resumes (\"cannot be used\"): $approx"
if [ "$frames" != "$NFRAMES" ] || [ "$bad" != 0 ] || [ "$temps" != 0 ] || [ "$lock" != 0 ] || [ "$other" != 0 ] ||
    [ "$checks" != equal ] || [ "$approx" != 0 ] || [ "$fails" != 0 ]; then
    echo "FAIL"
    exit 1
fi
echo "PASS"
