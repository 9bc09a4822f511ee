#!/bin/sh
# Configurations and helpers are called through variables, which shellcheck cannot see:
# shellcheck disable=SC2317
#
# vdbturb benchmark harness: runs named configurations and reports, per configuration, the median seconds
# per frame, the total time, the peak RSS, the thread count and the machine, all taken from the summary
# line the timed command prints with --json; and, measured here, the CPU time the command used, the load
# average before and after it, and its seconds per frame at the 5th and at the last frame (growth). Each
# run appends a row to docs/performance.md.
#
# A benchmark, not a test: nothing here fails because the machine is busy. A configuration whose command
# or data is missing is reported as "not available yet" and skipped; only a command that runs and fails
# makes the harness exit 1.
#
#   bench/run.sh --list
#   bench/run.sh [--vdbturb PATH] [--work DIR] [--threads N] [--frames N] [--no-record] CONFIG...
#
# POSIX sh and coreutils only (no python, no jq), so it runs on a fresh Debian 12 after
# tools/setup-debian12.sh. The blender-* configurations also need Blender (apt-get install blender).
set -eu

ROOT=$(cd "$(dirname "$0")/.." && pwd)
DATA="$(cd "$ROOT/.." && pwd)/shared/data"
VDBTURB=""
WORK="${VDBTURB_BENCH_WORK:-${TMPDIR:-/tmp}/vdbturb-bench}"
THREADS=""
FRAMES_OVERRIDE=""
RECORD=1
PERF="$ROOT/docs/performance.md"

CONFIGS="tiny measure-plume sim128 paper3d transfer2d plume4x box32 box64 box128 box256 synthbox32 synthbox64 synthbox128 synthbox256 blender-paper3d blender-plume2 ratio2 blender-noise synth2d synth3d
 stylize1m stylize1m-full fluidy12k fluidy123k animate640 animate640-preview animate640-sequence"

describe() {
    case "$1" in
    tiny) echo "CI smoke test of the harness: measure on 2 frames of the Blender plume pair, no spectra" ;;
    measure-plume) echo "measure: blender-plume-128 (output and source) against blender-plume-32 (target), frames 1-10, with spectra" ;;
    sim128) echo "sim: built-in scene plume at 128x128x192, 30 frames (the paper's same-size simulation: 50 s/frame)" ;;
    paper3d) echo "transfer: plume 16x16x24 (target) -> swirl 128x128x192 (source), 30 frames (paper: 270 s/frame)" ;;
    transfer2d) echo "transfer: 2D, plume 24x32 (target) -> swirl 192x256 (source), one z layer, 30 frames (paper: 0.7 s/frame; target <= 0.1)" ;;
    plume4x) echo "transfer: blender-plume-32 (target) -> blender-plume-128 (source), the 10 frames both hold" ;;
    box32|box64|box128|box256) echo "transfer: plume4x with the target's domain grown to ${1#box}^3 coarse cells (the same smoke, ratio 4), frames 1-10 (cost follows the smoke)" ;;
    synthbox32|synthbox64|synthbox128|synthbox256) echo "synth: the box${1#synthbox} target (blender-plume-32 in a ${1#synthbox}^3 domain, the same smoke), factor 4, frames 1-3 (cost follows the smoke)" ;;
    blender-paper3d) echo "transfer: Blender plume 16x16x24 (target) -> Blender two-jet swirl 128x128x192 (source), 30 frames (baked by bench/blender_pairs.sh)" ;;
    blender-plume2) echo "transfer: blender-plume2-32 (target) -> blender-plume2-128 (source), 30 frames (ratio 4)" ;;
    ratio2) echo "transfer: blender-plume2-128 box-downsampled to 64^3 (target) -> blender-plume2-128 (source), 30 frames (ratio 2)" ;;
    blender-noise) echo "Blender 3.4 Mantaflow: the blender-paper3d plume 16x16x24 with its Noise up-res x8 (128x128x192), 30 frames, base sim included" ;;
    synth2d) echo "synth: 2D, analytic vortex 64x64x1 -> 256x256 (factor 4), 30 frames (paper: about 1 min)" ;;
    synth3d) echo "synth: 3D, coarse plume 64x64x16 -> 256x256x64 (factor 4), 30 frames (paper: about 1 h single-threaded)" ;;
    stylize1m) echo "stylize: 1024x1024 rotating blob (0.37 Mpix of fluid), 256^2 exemplar, 5 frames (paper: 5 min per 1-Mpix frame, 4 cores)" ;;
    stylize1m-full) echo "stylize: 1024x1024 all fluid (1.05 Mpix of patches), 256^2 exemplar, 3 frames (the worst case)" ;;
    animate640) echo "animate: 640x480 still (built-in river, matte, scenes/animate strokes), 100-frame 640x480 example read from PNGs, HM steerable x3 on the auto grid (target: <= 60 s, <= 2 GiB)" ;;
    animate640-preview) echo "animate: the same with the Laplacian single-pass preview matching" ;;
    animate640-sequence) echo "animate: the same with --hm-apply sequence (the mean frame matched once, per-frame cell moments)" ;;
    fluidy12k) echo "stylize fluidymation: 12k masked pixels (rotate 204^2), builtin:ink 240x180x20, 10 frames (paper Table 2: 0.55 s/frame, 4 cores)" ;;
    fluidy123k) echo "stylize fluidymation: 123k masked pixels (rotate 652^2), builtin:ink 400x300x30, 10 frames (paper Table 2: 3.48 s/frame, 4 cores)" ;;
    *) return 1 ;;
    esac
}

usage() {
    sed -n "5,17p" "$0" | sed "s/^# \{0,1\}//"
    echo "configurations:"
    for c in $CONFIGS; do printf '  %-16s %s\n' "$c" "$(describe "$c")"; done
}

log() { printf 'bench: %s\n' "$*" >&2; }

while [ $# -gt 0 ]; do
    case "$1" in
    --list|-h|--help) usage; exit 0 ;;
    --vdbturb) VDBTURB=$2; shift 2 ;;
    --work) WORK=$2; shift 2 ;;
    --threads) THREADS=$2; shift 2 ;;
    --frames) FRAMES_OVERRIDE=$2; shift 2 ;;
    --no-record) RECORD=0; shift ;;
    --*) echo "bench: unknown option $1" >&2; usage >&2; exit 2 ;;
    *) break ;;
    esac
done
[ $# -gt 0 ] || { usage >&2; exit 2; }
for c in "$@"; do describe "$c" >/dev/null || { echo "bench: unknown configuration '$c' (see --list)" >&2; exit 2; }; done

if [ -z "$VDBTURB" ]; then
    for cand in "$ROOT/build/tools/vdbturb" "$ROOT"/build-*/tools/vdbturb; do
        if [ -x "$cand" ]; then VDBTURB=$cand; break; fi
    done
    [ -n "$VDBTURB" ] || VDBTURB=$(command -v vdbturb || true)
fi
if [ -z "$VDBTURB" ] || [ ! -x "$VDBTURB" ]; then
    echo "bench: no vdbturb binary: build it (tools/build.sh) or pass --vdbturb" >&2
    exit 2
fi
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd) # absolute: some configurations run in a directory of their own
THREAD_ARGS=""
[ -z "$THREADS" ] || THREAD_ARGS="--threads $THREADS"

now() { date +%s.%N 2>/dev/null || date +%s; }
elapsed() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", b - a }'; }
load1() { cut -d ' ' -f 1 /proc/loadavg 2>/dev/null || echo "?"; }
# child_cpu: sets CPU to the user + system CPU seconds of this shell's finished children. `times` must run
# in this shell, never in a command substitution (a fork reports its own children), so it writes a file.
child_cpu() {
    times > "$WORK/.times.$$"
    CPU=$(awk 'NR == 2 { s = 0; for (i = 1; i <= 2; i++) { split($i, a, "m"); sub("s", "", a[2]); s += a[1] * 60 + a[2] }
        printf "%.2f", s }' "$WORK/.times.$$")
    rm -f "$WORK/.times.$$"
}

# per_frame JSONL: "frame seconds" for each per-frame line (not the summary), in the order written.
per_frame() {
    grep -v '"summary":true' "$1" | grep '"seconds":' | awk '{
        f = ""; s = ""
        if (match($0, /"frame":[0-9-]+/)) f = substr($0, RSTART + 8, RLENGTH - 8)
        if (match($0, /"seconds":[0-9.eE+-]+/)) s = substr($0, RSTART + 10, RLENGTH - 10)
        if (f != "" && s != "") print f, s }' || true
}
# growth JSONL: "s/frame at the 5th frame -> at the last (last/5th)", or at the first when fewer than 5 ran.
growth() {
    per_frame "$1" | awk '{ n++; s[n] = $2; f[n] = $1 } END {
        if (n == 0) { print "-"; exit }
        k = n >= 5 ? 5 : 1
        printf "f%s %.2f -> f%s %.2f (x%.1f)", f[k], s[k], f[n], s[n], (s[k] > 0 ? s[n] / s[k] : 0) }'
}
# steps JSONL FRAME: the frame's steps_s (transfer, synth, stylize), largest first, "total" left out, then
# "outside": the frame's seconds less steps_s.total (reading, writing, reporting).
steps() {
    l=$(grep -v '"summary":true' "$1" | grep "\"frame\":$2[,}]" | tail -n 1)
    sec=$(printf '%s\n' "$l" | sed -n 's/.*"seconds":\([0-9.eE+-]*\).*/\1/p')
    printf '%s\n' "$l" | sed -n 's/.*"steps_s":{\([^}]*\)}.*/\1/p' | tr ',' '\n' | tr -d '"' |
        awk -F ':' -v sec="$sec" '$1 == "total" && sec != "" { printf "%.6f outside\n", sec - $2 } $1 != "total" && $2 != "" { print $2, $1 }' |
        sort -rn | awk '{ printf "%s%s %.2f", (NR > 1 ? ", " : ""), $2, $1 }'
}

# --- availability -----------------------------------------------------------------------------------

REASON=""
# need_command SUB [OPTION...]: the subcommand exists and its --help mentions every option.
need_command() {
    sub=$1; shift
    if ! "$VDBTURB" --help 2>/dev/null | grep -Eq "^ +$sub( |$)"; then
        REASON="vdbturb has no '$sub' command yet"; return 1
    fi
    # --help-all: the second tier of settings too (--help lists the everyday options only).
    help=$("$VDBTURB" "$sub" --help-all 2>&1 || "$VDBTURB" "$sub" --help 2>&1 || true)
    for o in "$@"; do
        case "$help" in
        *"$o"*) ;;
        *) REASON="vdbturb $sub has no $o option yet (adapt bench/run.sh)"; return 1 ;;
        esac
    done
}
need_data() {
    for d in "$@"; do
        [ -d "$DATA/$d" ] || { REASON="missing data $DATA/$d"; return 1; }
    done
}
BLENDER=${BLENDER:-blender}
need_blender() {
    command -v "$BLENDER" >/dev/null 2>&1 || { REASON="no '$BLENDER' on PATH (Debian 12: apt-get install blender)"; return 1; }
}

# --- running ----------------------------------------------------------------------------------------

# prepare NAME LASTFILE COMMAND...: runs an untimed preparation step unless LASTFILE already exists.
prepare() {
    pname=$1; plast=$2; shift 2
    if [ -f "$plast" ]; then log "$pname: reusing $(dirname "$plast")"; return 0; fi
    log "$pname (preparation, not timed): $*"
    "$@" >/dev/null || { REASON="preparation '$pname' failed"; return 1; }
}

# timed CONFIG COMMAND...: runs the measured command with --json; its summary line gives the numbers.
RESULTS="$WORK/results.$$"
: > "$RESULTS"
FAILED=0
timed() {
    cfg=$1; shift
    out="$WORK/$cfg.jsonl"
    load0=$(load1)
    log "$cfg: $* (load average $load0)"
    child_cpu
    cpu0=$CPU
    t0=$(now)
    set +e
    "$@" > "$out"
    rc=$?
    set -e
    t1=$(now)
    child_cpu
    cpu=$(awk -v a="$cpu0" -v b="$CPU" 'BEGIN { printf "%.1f", b - a }')
    load=$load0"->"$(load1)
    wall=$(elapsed "$t0" "$t1")
    summary=$(grep '"summary":true' "$out" | tail -n 1 || true)
    if [ "$rc" -ne 0 ] || [ -z "$summary" ]; then
        log "$cfg: FAILED (exit $rc, ${wall} s); per-frame lines in $out"
        printf '%s\tFAILED (exit %s)\n' "$cfg" "$rc" >> "$RESULTS"
        FAILED=1
        return 0
    fi
    field() { printf '%s\n' "$summary" | sed -n "s/.*\"$1\":\([^,}]*\).*/\1/p"; }
    frames=$(field frames)
    median=$(field median_s_per_frame)
    total=$(field total_s)
    rss=$(field peak_rss_mb)
    threads=$(field threads)
    machine=$(printf '%s\n' "$summary" | sed -n 's/.*"machine":"\([^"]*\)".*/\1/p')
    [ -n "$machine" ] || machine="$(grep -m1 'model name' /proc/cpuinfo | sed 's/.*: //') ($(nproc) threads)"
    grow=$(growth "$out")
    line=$(awk -v c="$cfg" -v f="$frames" -v m="$median" -v t="$total" -v w="$wall" -v r="$rss" -v th="$threads" -v mc="$machine" \
        -v cpu="$cpu" -v ld="$load" -v g="$grow" \
        'BEGIN { printf "%s\t%s\t%.3f\t%.1f\t%.1f\t%.0f\t%s\t%s\t%s\t%s\t%s", c, f, m, t, w, r, th, mc, cpu, ld, g }')
    printf '%s\n' "$line" >> "$RESULTS"
    # Where the time went at the 5th and the last frame, for commands that report steps_s.
    per_frame "$out" | awk 'NR == 5 || NR == 1 { print $1 } { l = $1 } END { print l }' | sort -un | while read -r fr; do
        st=$(steps "$out" "$fr")
        [ -z "$st" ] || log "$cfg: frame $fr steps_s: $st"
    done
    if [ "$RECORD" = 1 ]; then record "$line" "$*"; fi
}

record() {
    if [ ! -f "$PERF" ]; then
        log "no $PERF: not recording"
        return 0
    fi
    rev=$(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null || echo unknown)
    if [ -n "$(git -C "$ROOT" status --porcelain --untracked-files=no 2>/dev/null || true)" ]; then rev="$rev+dirty"; fi
    # Paths in the table are relative to the repository, so rows compare across machines.
    cmd=$(printf '%s' "$2" | sed -e "s#$DATA#../shared/data#g" -e "s#$ROOT/##g" -e "s#$WORK#WORK#g")
    printf '%s\n' "$1" | awk -F '\t' -v d="$(date -u +%Y-%m-%d)" -v rev="$rev" -v cmd="$cmd" \
        '{ printf "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | `%s` | %s | %s | %s |\n", d, $1, $2, $3, $4, $5, $6, $7, $8, rev, cmd, $9, $10, $11 }' >> "$PERF"
}

frames_or() { if [ -n "$FRAMES_OVERRIDE" ]; then echo "$FRAMES_OVERRIDE"; else echo "$1"; fi; }

# --- configurations ---------------------------------------------------------------------------------
# Each returns non-zero with REASON set when it cannot run here yet.

cfg_tiny() {
    need_command measure --output --target --no-spectra && need_data blender-plume-32 blender-plume-128 || return 1
    # shellcheck disable=SC2086
    timed tiny "$VDBTURB" measure $THREAD_ARGS --output "$DATA/blender-plume-128/fluid_data_####.vdb" \
        --target "$DATA/blender-plume-32/fluid_data_####.vdb" --frames 9-10 --no-spectra -q
}

cfg_measure_plume() {
    need_command measure --output --target --source && need_data blender-plume-32 blender-plume-128 || return 1
    n=$(frames_or 10)
    # shellcheck disable=SC2086
    timed measure-plume "$VDBTURB" measure $THREAD_ARGS --output "$DATA/blender-plume-128/fluid_data_####.vdb" \
        --target "$DATA/blender-plume-32/fluid_data_####.vdb" --source "$DATA/blender-plume-128/fluid_data_####.vdb" \
        --frames "1-$n"
}

cfg_sim128() {
    need_command sim --res --frames --seed --out --json || return 1
    n=$(frames_or 30)
    d="$WORK/sim128_f$n"
    # shellcheck disable=SC2086
    timed sim128 "$VDBTURB" sim plume $THREAD_ARGS --res 128x128x192 --frames "$n" --seed 1 --out "$d/plume.####.vdb" --json
}

# A transfer between two built-in scenes: plume at TRES (target) and swirl at SRES (source), seed 1, simulated once
# by untimed preparation steps and reused; the timed command is the transfer into WORK/NAME_out.
transfer_sim_pair() {
    name=$1; tres=$2; sres=$3
    need_command sim --res --frames --seed --out && need_command transfer --target --source --out --json || return 1
    n=$(frames_or 30)
    t="$WORK/plume_${tres}_s1_f$n"
    s="$WORK/swirl_${sres}_s1_f$n"
    last=$(printf '%04d' "$n")
    # shellcheck disable=SC2086
    prepare "target: sim plume $tres" "$t/plume.$last.vdb" \
        "$VDBTURB" sim plume $THREAD_ARGS --res "$tres" --frames "$n" --seed 1 --out "$t/plume.####.vdb" -q || return 1
    # shellcheck disable=SC2086
    prepare "source: sim swirl $sres" "$s/swirl.$last.vdb" \
        "$VDBTURB" sim swirl $THREAD_ARGS --res "$sres" --frames "$n" --seed 1 --out "$s/swirl.####.vdb" -q || return 1
    rm -rf "$WORK/${name}_out"
    # shellcheck disable=SC2086
    timed "$name" "$VDBTURB" transfer $THREAD_ARGS --target "$t/plume.####.vdb" --source "$s/swirl.####.vdb" \
        --out "$WORK/${name}_out/up.####.vdb" --json
}

cfg_paper3d() { transfer_sim_pair paper3d 16x16x24 128x128x192; }

# transfer2d: the paper's 2D configuration (Sato et al.: 24x32 target, 192x256 source, 0.7 s/frame) on the built-in
# scenes simulated in 2D.
cfg_transfer2d() { transfer_sim_pair transfer2d 24x32x1 192x256x1; }

cfg_plume4x() {
    need_command transfer --target --source --out --frames --json && need_data blender-plume-32 blender-plume-128 || return 1
    n=$(frames_or 10)
    rm -rf "$WORK/plume4x_out"
    # shellcheck disable=SC2086
    timed plume4x "$VDBTURB" transfer $THREAD_ARGS --target "$DATA/blender-plume-32/fluid_data_####.vdb" \
        --source "$DATA/blender-plume-128/fluid_data_####.vdb" --out "$WORK/plume4x_out/up.####.vdb" --frames "1-$n" --json
}

# box32..box256: blender-plume-32 with its Blender domain grown to N^3 (vdbturb_bench_pad, untimed), the same
# source; the output box follows the smoke, so the four should cost about the same.
# padded_box N FRAMES: sets t to blender-plume-32's first FRAMES frames padded to an N^3 domain (prepared once).
padded_box() {
    nbox=$1
    pn=$2
    pad="$(dirname "$VDBTURB")/vdbturb_bench_pad"
    [ -x "$pad" ] || { REASON="no $pad (build target vdbturb_bench_pad)"; return 1; }
    need_data blender-plume-32 || return 1
    t="$WORK/plume32_box$nbox"
    last=$(printf '%04d' "$pn")
    if [ ! -f "$t/fluid_data_$last.vdb" ]; then
        log "box$nbox (preparation, not timed): $pad into $t"
        mkdir -p "$t"
        i=1
        while [ "$i" -le "$pn" ]; do
            fr=$(printf '%04d' "$i")
            "$pad" "$DATA/blender-plume-32/fluid_data_$fr.vdb" "$t/fluid_data_$fr.vdb" "$nbox" || { REASON="padding failed"; return 1; }
            i=$((i + 1))
        done
    fi
}
cfg_box() {
    need_command transfer --target --source --out --frames --json && need_data blender-plume-128 || return 1
    n=$(frames_or 10)
    padded_box "$1" "$n" || return 1
    rm -rf "$WORK/box${nbox}_out"
    # shellcheck disable=SC2086
    timed "box$nbox" "$VDBTURB" transfer $THREAD_ARGS --target "$t/fluid_data_####.vdb" \
        --source "$DATA/blender-plume-128/fluid_data_####.vdb" --out "$WORK/box${nbox}_out/up.####.vdb" --frames "1-$n" --json
}
cfg_box32() { cfg_box 32; }
cfg_box64() { cfg_box 64; }
cfg_box128() { cfg_box 128; }
cfg_box256() { cfg_box 256; }
cfg_synthbox() {
    need_command synth --target --factor --out --frames --json || return 1
    n=$(frames_or 3)
    padded_box "$1" 10 || return 1
    rm -rf "$WORK/synthbox${nbox}_out"
    # shellcheck disable=SC2086
    timed "synthbox$nbox" "$VDBTURB" synth $THREAD_ARGS --target "$t/fluid_data_####.vdb" --factor 4 \
        --out "$WORK/synthbox${nbox}_out/up.####.vdb" --frames "1-$n" --json
}
cfg_synthbox32() { cfg_synthbox 32; }
cfg_synthbox64() { cfg_synthbox 64; }
cfg_synthbox128() { cfg_synthbox 128; }
cfg_synthbox256() { cfg_synthbox 256; }

# blender-paper3d: the paper's 3D configuration as Blender 3.4 caches, baked once by bench/blender_pairs.sh
# (untimed) and reused; a bake already in WORK is used even where Blender is not installed.
cfg_blender_paper3d() {
    need_command transfer --target --source --out --frames --json || return 1
    n=$(frames_or 30)
    b="$WORK/blender"
    t="$b/plume_16x16x24_f30/data"
    s="$b/swirl2jet_128x128x192_f30/data"
    if [ ! -f "$t/fluid_data_0030.vdb" ] || [ ! -f "$s/fluid_data_0030.vdb" ]; then
        need_blender || { REASON="no baked pair in $b and $REASON"; return 1; }
        # shellcheck disable=SC2086
        prepare "Blender pair: bench/blender_pairs.sh" "$s/fluid_data_0030.vdb" \
            "$ROOT/bench/blender_pairs.sh" --work "$WORK" --frames 30 ${THREADS:+--threads "$THREADS"} || return 1
    fi
    rm -rf "$WORK/blender_paper3d_out"
    # shellcheck disable=SC2086
    timed blender-paper3d "$VDBTURB" transfer $THREAD_ARGS --target "$t/fluid_data_####.vdb" --source "$s/fluid_data_####.vdb" \
        --out "$WORK/blender_paper3d_out/up.####.vdb" --frames "1-$n" --json
}

cfg_blender_plume2() {
    need_command transfer --target --source --out --frames --json && need_data blender-plume2-32 blender-plume2-128 || return 1
    n=$(frames_or 30)
    rm -rf "$WORK/blender_plume2_out"
    # shellcheck disable=SC2086
    timed blender-plume2 "$VDBTURB" transfer $THREAD_ARGS --target "$DATA/blender-plume2-32/fluid_data_####.vdb" \
        --source "$DATA/blender-plume2-128/fluid_data_####.vdb" --out "$WORK/blender_plume2_out/up.####.vdb" --frames "1-$n" --json
}

# ratio2: the most common production up-res (x2); the 64^3 target is the 128^3 Blender plume box-averaged.
cfg_ratio2() {
    need_command resample --down --out --style && need_command transfer --target --source --out --frames --json &&
        need_data blender-plume2-128 || return 1
    n=$(frames_or 30)
    t="$WORK/plume2_64_down2"
    # shellcheck disable=SC2086
    prepare "target: resample --down 2 blender-plume2-128" "$t/fluid_data_0030.vdb" \
        "$VDBTURB" resample $THREAD_ARGS --down 2 --style blender --out "$t/fluid_data_####.vdb" -q \
        "$DATA/blender-plume2-128/fluid_data_####.vdb" || return 1
    rm -rf "$WORK/ratio2_out"
    # shellcheck disable=SC2086
    timed ratio2 "$VDBTURB" transfer $THREAD_ARGS --target "$t/fluid_data_####.vdb" \
        --source "$DATA/blender-plume2-128/fluid_data_####.vdb" --out "$WORK/ratio2_out/up.####.vdb" --frames "1-$n" --json
}

# blender-noise: what a Blender user runs instead of transfer. The bake folder is emptied first: a REPLAY
# cache finding earlier files would read them instead of simulating.
cfg_blender_noise() {
    need_blender || return 1
    n=$(frames_or 30)
    o="$WORK/blender_noise_out"
    rm -rf "$o"
    mkdir -p "$o"
    # Mantaflow's noise writes its wavelet tile (waveletNoiseTile.bin) into the working directory: run it in $o.
    here=$(pwd)
    cd "$o"
    timed blender-noise "$BLENDER" -b --factory-startup -t "${THREADS:-0}" --python "$ROOT/bench/blender/plume_noise.py" -- \
        "$o" "$n" 8 24 "${THREADS:-0}"
    cd "$here"
}

# synth2d: an analytic vortex as the coarse flow (no preparation); synth3d: the plume scene simulated once.
cfg_synth2d() {
    need_command synth --flow --flow-res --frames --factor --out --json || return 1
    n=$(frames_or 30)
    rm -rf "$WORK/synth2d_out"
    # shellcheck disable=SC2086
    timed synth2d "$VDBTURB" synth $THREAD_ARGS --flow vortex --flow-res 64x64x1 --frames "$n" --factor 4 \
        --out "$WORK/synth2d_out/up.####.vdb" --json
}

cfg_synth3d() {
    need_command sim --res --frames --seed --out && need_command synth --target --factor --out --json || return 1
    n=$(frames_or 30)
    c="$WORK/plume_64x64x16_s1_f$n"
    last=$(printf '%04d' "$n")
    # shellcheck disable=SC2086
    prepare "coarse flow: sim plume 64x64x16" "$c/plume.$last.vdb" \
        "$VDBTURB" sim plume $THREAD_ARGS --res 64x64x16 --frames "$n" --seed 1 --out "$c/plume.####.vdb" -q || return 1
    rm -rf "$WORK/synth3d_out"
    # shellcheck disable=SC2086
    timed synth3d "$VDBTURB" synth $THREAD_ARGS --target "$c/plume.####.vdb" --factor 4 --out "$WORK/synth3d_out/up.####.vdb" --json
}

# stylize: built-in 2D targets and the procedural exemplar (no preparation).
cfg_stylize1m() {
    need_command stylize --scene --scene-size --frames --exemplar --out --json || return 1
    n=$(frames_or 5)
    rm -rf "$WORK/stylize1m_out"
    # shellcheck disable=SC2086
    timed stylize1m "$VDBTURB" stylize $THREAD_ARGS --scene rotate --scene-size 1024x1024 --frames "$n" \
        --exemplar builtin:fire:256 --out "$WORK/stylize1m_out/s.####.exr" --json
}

cfg_stylize1m_full() {
    need_command stylize --scene --scene-size --frames --exemplar --out --json || return 1
    n=$(frames_or 3)
    rm -rf "$WORK/stylize1m_full_out"
    # shellcheck disable=SC2086
    timed stylize1m-full "$VDBTURB" stylize $THREAD_ARGS --scene fill --scene-size 1024x1024 --frames "$n" \
        --exemplar builtin:fire:256 --out "$WORK/stylize1m_full_out/s.####.exr" --json
}

# animate640: the example (100 PNG frames) and the still are written once by an untimed preparation
# step; the timed command reads them, as a TD's run would. N - tau = 84 frames come out.
animate_inputs() {
    a="$WORK/animate640_in"
    prepare "example: built-in river 640x480x$1" "$a/river.$(printf '%04d' "$1").png" \
        "$VDBTURB" animate --export-builtin "$a" --example "builtin:river:640x480x$1" --target builtin:river:640x480 -q
}

# One timed animate640 run: $1 = configuration name, $2 = output folder under $WORK, then extra options.
animate640_run() {
    name=$1 out=$2
    shift 2
    need_command animate --example --target --target-alpha --flow-strokes --hm --out --json || return 1
    n=$(frames_or 100)
    animate_inputs "$n" || return 1
    rm -rf "$WORK/$out"
    # shellcheck disable=SC2086
    timed "$name" "$VDBTURB" animate $THREAD_ARGS --example "$WORK/animate640_in/river.####.png" --frames "1-$n" \
        --target "$WORK/animate640_in/still.png" --target-alpha "$WORK/animate640_in/matte.png" \
        --flow-strokes "$ROOT/scenes/animate/river_strokes.json" "$@" --out "$WORK/$out/a.####.exr" --json
}

cfg_animate640() { animate640_run animate640 animate640_out; }
cfg_animate640_preview() { animate640_run animate640-preview animate640_preview_out --hm laplacian; }
cfg_animate640_sequence() { animate640_run animate640-sequence animate640_sequence_out --hm-apply sequence; }

# stylize --method fluidymation: the masked-pixel counts of the paper's Table 2 (built-in target and
# moving exemplar; no preparation).
fluidy() {
    need_command stylize --method --scene --scene-size --frames --exemplar --out --json || return 1
    n=$(frames_or 10)
    rm -rf "$WORK/$1_out"
    # shellcheck disable=SC2086
    timed "$1" "$VDBTURB" stylize $THREAD_ARGS --method fluidymation --scene rotate --scene-size "$2" --frames "$n" \
        --exemplar "$3" --out "$WORK/$1_out/s.####.png" --json
}
cfg_fluidy12k() { fluidy fluidy12k 204x204 builtin:ink:240x180x20; }
cfg_fluidy123k() { fluidy fluidy123k 652x652 builtin:ink:400x300x30; }

# --- main -------------------------------------------------------------------------------------------

log "vdbturb: $VDBTURB; work: $WORK; machine: $(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | sed 's/.*: //') ($(nproc) threads)"
for c in "$@"; do
    fn="cfg_$(printf '%s' "$c" | tr '-' '_')"
    REASON=""
    if ! "$fn"; then
        log "$c: not available yet: $REASON"
        printf '%s\tnot available yet: %s\n' "$c" "$REASON" >> "$RESULTS"
    fi
done

printf '%-15s %6s %14s %8s %8s %8s %11s %7s %-12s %-30s %s\n' config frames "median s/frame" "total s" "wall s" "cpu s" \
    "peak RSS MB" threads load "s/frame 5th -> last" machine
while IFS="$(printf '\t')" read -r c f m t w r th mc cpu ld g; do
    case "$f" in
    FAILED*|not\ available*) printf '%-15s %s\n' "$c" "$f" ;;
    *) printf '%-15s %6s %14s %8s %8s %8s %11s %7s %-12s %-30s %s\n' "$c" "$f" "$m" "$t" "$w" "$cpu" "$r" "$th" "$ld" "$g" "$mc" ;;
    esac
done < "$RESULTS"
rm -f "$RESULTS"
[ "$RECORD" = 0 ] || [ ! -f "$PERF" ] || log "rows appended to $PERF"
exit $FAILED
