#!/bin/sh
# The measurements behind docs/animate.md (Okabe et al., `vdbturb animate`). Not a test: it prints numbers
# and writes pictures into $WORK; docs/animate.md quotes them.
#
#   bench/animate_quality.sh [--vdbturb PATH] [--work DIR] sweep|river|plume|stationary|steady64|clone|modes|all
#
#   sweep  A' against the true average: a frame of the example is the target and the example's own flow
#          the design, so the best A' is the example's average A; rms(A' - A) / rms(F - A) for Sh x w_a,
#          on the built-in river and on renders of the Blender plume (blender-plume2-128).
#   river  the built-in river: still, matte and strokes (scenes/animate), --measure, sheet, JSON
#   plume  the Blender cache blender-plume2-128 through the front camera as the example, a render of
#          the other plume (blender-plume-128, side view) as the still, --measure, sheet, JSON; with
#          --hm-apply per-frame (the paper) and sequence, and without histogram matching
#   stationary  the same still and strokes with a steady, textured Blender plume as the example: baked
#          here by bench/blender_plume_textured.py (needs Debian's blender; RES=64 by default, 120 frames,
#          frames 60-120 used), both --hm-apply modes and --hm off
#   steady64  the shared steady Blender plume (blender-steady-64, frames 91-160) through the front camera as the
#          example, its projected velocity the truth of its motion: onto the plume still above and onto the steady
#          plume itself seen from the side (frame 125), each with plume_strokes.json (the example's speed) and
#          with the same strokes at 2 px/frame; per-frame and sequence matching; the example's v as chosen
#          (analysis.givenFlow best) and as the cache's velocity (use); how fast the renders' texture moves against
#          the cache's velocity (bench/animate_pattern_speed.py, needs /usr/bin/python3 with numpy): per band of
#          rows, and a kymograph
#   clone  the Clone Brush: the steady plume's column (blender-steady-64 front) cloned along the plume still's axis
#          (scenes/animate/plume_clone.json), --hm-apply sequence, 2 px/frame upward, with and without the clone:
#          --measure, and a picture (example + source stroke, R' without and with the clone, output frames); the same
#          on the built-in river (river_clone.json: the example's mid-stream along the still's curved river)
#   modes  steerable (HM Rep 1, 3) against the Laplacian preview on the river: time and errors
# Needs POSIX sh, coreutils and oiiotool (Debian openimageio-tools); `stationary` also blender, `steady64` python3-numpy.
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
DATA="$(cd "$ROOT/.." && pwd)/shared/data"
VDBTURB="$ROOT/build/tools/vdbturb"
WORK="${TMPDIR:-/tmp}/vdbturb-animate-quality"
while [ $# -gt 0 ]; do
    case "$1" in
    --vdbturb) VDBTURB=$2; shift 2 ;;
    --work) WORK=$2; shift 2 ;;
    -h|--help) sed -n "2,29p" "$0" | sed "s/^# \{0,1\}//"; exit 0 ;;
    *) break ;;
    esac
done
[ $# -gt 0 ] || { echo "usage: $0 [--vdbturb PATH] [--work DIR] sweep|river|plume|stationary|steady64|clone|modes|all" >&2; exit 2; }
mkdir -p "$WORK"
STROKES="$ROOT/scenes/animate"
log() { printf 'animate-quality: %s\n' "$*" >&2; }
rms() { oiiotool "$1" "$2" --diff 2>&1 | sed -n 's/.*RMS error = \([0-9.e+-]*\).*/\1/p' | head -1; }

# A' error relative to the differences, for one example: $1 = name, $2 = example pattern, $3 = target
# frame file, $4 = flow EXR (the example's v), $5 = A.exr (the example's average).
sweep_one() {
    base=$(rms "$5" "$3")
    for sh in 0 4 8 16 32; do
        for wa in 0 2 4 8 16; do
            d="$WORK/sweep/${1}_${sh}_${wa}"
            rm -rf "$d"
            "$VDBTURB" animate --example "$2" --target "$3" --flow "$4" --tau 2 --hm off --shutter "$sh" --wa "$wa" \
                --out "$d/o/o.####.png" --dump "$d/dump" -q
            e=$(rms "$5" "$d/dump/Aprime.exr")
            printf '%s %s %s %s\n' "$1" "$sh" "$wa" "$(echo "$e $base" | awk '{printf "%.3f", $1 / $2}')"
            rm -rf "$d"
        done
    done
}

do_sweep() {
    S="$WORK/sweep"
    mkdir -p "$S"
    "$VDBTURB" animate --export-builtin "$S/river" --example builtin:river:160x120x48 --target builtin:river:160x120 -q
    "$VDBTURB" animate --example "$S/river/river.####.png" --target "$S/river/river.0024.png" --flow-strokes "$STROKES/river_strokes.json" \
        --tau 2 --hm off --out "$S/r0/o.####.png" --dump "$S/river_dump" -q
    "$VDBTURB" preview "$DATA/blender-plume2-128/fluid_data_####.vdb" --width 256 --out "$S/plume/p.####.png" -q
    "$VDBTURB" animate --example-cache "$DATA/blender-plume2-128/fluid_data_####.vdb" --width 256 --target "$S/plume/p.0015.png" \
        --flow-strokes "$STROKES/plume_strokes.json" --tau 2 --hm off --out "$S/p0/o.####.png" --dump "$S/plume_dump" -q
    {
        echo "example Sh w_a rel_rms"
        sweep_one river "$S/river/river.####.png" "$S/river/river.0024.png" "$S/river_dump/v.exr" "$S/river_dump/A.exr"
        sweep_one plume "$S/plume/p.####.png" "$S/plume/p.0015.png" "$S/plume_dump/v.exr" "$S/plume_dump/A.exr"
    } | tee "$WORK/sweep.txt"
}

do_river() {
    R="$WORK/river"
    rm -rf "$R"
    "$VDBTURB" animate --export-builtin "$R/in" --example builtin:river:320x240x60 --target builtin:river:320x240 -q
    "$VDBTURB" animate --example "$R/in/river.####.png" --target "$R/in/still.png" --target-alpha "$R/in/matte.png" \
        --flow-strokes "$STROKES/river_strokes.json" --out "$R/out/river.####.png" --sheet "$R/sheet.png" --dump "$R/dump" \
        --measure --json > "$R/run.jsonl"
    tail -1 "$R/run.jsonl"
}

# The plume's still and matte: the other plume (blender-plume-128), frame 30 from the side; the matte from the
# render's opacity. $1 = directory.
plume_still() {
    "$VDBTURB" preview "$DATA/blender-plume-128/fluid_data_####.vdb" --frames 30 --view side --width 256 --out "$1/still.####.png" -q
    oiiotool "$1/still.0030.png" --subc 0.07,0.075,0.09 --abs --chsum --subc 0.03 --mulc 6 --clamp:min=0:max=1 -o "$1/matte.png"
}

# One animate run of a cache example onto the plume still, per histogram-matching mode; prints the summary line
# per mode. $1 = directory (with still and matte), $2 = cache pattern, $3 = tau, then extra options.
plume_runs() {
    dir=$1 cache=$2 tau=$3
    shift 3
    for mode in per-frame sequence off; do
        if [ "$mode" = off ]; then hm="--hm off"; else hm="--hm-apply $mode"; fi
        # shellcheck disable=SC2086
        "$VDBTURB" animate --example-cache "$cache" --camera front --width 256 "$@" \
            --target "$dir/still.0030.png" --target-alpha "$dir/matte.png" --flow-strokes "$STROKES/plume_strokes.json" \
            --tau "$tau" $hm --out "$dir/$mode/out.####.png" --sheet "$dir/sheet-$mode.png" --dump "$dir/dump-$mode" \
            --measure --json > "$dir/$mode.jsonl"
        printf '%s: ' "$mode"
        tail -1 "$dir/$mode.jsonl"
    done
}

do_plume() {
    P="$WORK/plume"
    rm -rf "$P"
    mkdir -p "$P"
    plume_still "$P"
    plume_runs "$P" "$DATA/blender-plume2-128/fluid_data_####.vdb" 8
}

do_stationary() {
    S="$WORK/stationary"
    res=${RES:-64}
    cache="$S/cache$res/data/fluid_data_####.vdb"
    if [ ! -f "$S/cache$res/data/fluid_data_0120.vdb" ]; then
        log "baking the textured plume at $res^3 (blender)"
        mkdir -p "$S"
        blender -b --factory-startup --python "$ROOT/bench/blender_plume_textured.py" -- "$res" "$S/cache$res" 120 > "$S/bake$res.log" 2>&1
        grep BAKE_SECONDS "$S/bake$res.log" >&2
    fi
    rm -rf "$S/run$res"
    mkdir -p "$S/run$res"
    plume_still "$S/run$res"
    plume_runs "$S/run$res" "$cache" 16 --frames 60-120
}

# One run of the steady cache: $1 = directory, $2 = tag, $3 = still, $4 = matte, $5 = strokes, then options. Prints
# the tag and the motion figures: the output's against the design (tracks, field), the example's against the cache.
# (sh has no local variables: the names differ from the callers'.)
steady_run() {
    sd=$1 stag=$2 sstill=$3 smatte=$4 sstrokes=$5
    shift 5
    "$VDBTURB" animate --example-cache "$DATA/blender-steady-64/fluid_data_####.vdb" --camera front --width 256 \
        --target "$sstill" --target-alpha "$smatte" --flow-strokes "$sstrokes" --tau 16 "$@" \
        --out "$sd/$stag/out.####.png" --sheet "$sd/sheet-$stag.png" --measure --json > "$sd/$stag.jsonl"
    tail -1 "$sd/$stag.jsonl" | python3 -c '
import json, sys
j = json.loads(sys.stdin.read()); q = j["quality"]; e = j["example"]
f = lambda k: "null" if q.get(k) is None else "%.2f" % q[k]
print("%s: design %.2f px/frame, v %s; output tracks %s deg %s, field %s deg %s; example tracks %s deg %s, field %s deg %s"
      % (sys.argv[1], j["design_mean_speed"], "given" if e["flow_given"] else "tracked",
         f("track_median_angle_deg"), f("track_median_speed_ratio"), f("flow_median_angle_deg"), f("flow_median_speed_ratio"),
         f("example_track_median_angle_deg"), f("example_track_median_speed_ratio"), f("example_flow_median_angle_deg"),
         f("example_flow_median_speed_ratio")))' "$stag"
}

do_steady64() {
    S="$WORK/steady64"
    cache="$DATA/blender-steady-64/fluid_data_####.vdb"
    rm -rf "$S"
    mkdir -p "$S"
    plume_still "$S"
    "$VDBTURB" preview "$cache" --frames 125 --view side --width 256 --out "$S/self.####.png" -q
    oiiotool "$S/self.0125.png" --subc 0.07,0.075,0.09 --abs --chsum --subc 0.03 --mulc 6 --clamp:min=0:max=1 -o "$S/selfmatte.png"
    sed 's/"speed": "example"/"speed": 2.0/' "$STROKES/plume_strokes.json" > "$S/strokes_2px.json"
    for still in plume self; do
        if [ $still = plume ]; then st="$S/still.0030.png" m="$S/matte.png"; else st="$S/self.0125.png" m="$S/selfmatte.png"; fi
        for design in example 2px; do
            if [ $design = example ]; then k="$STROKES/plume_strokes.json"; else k="$S/strokes_2px.json"; fi
            for mode in per-frame sequence; do
                steady_run "$S" "$still-$design-$mode" "$st" "$m" "$k" --hm-apply $mode
            done
        done
    done
    for mode in per-frame sequence; do
        steady_run "$S" "plume-example-$mode-cachev" "$S/still.0030.png" "$S/matte.png" "$STROKES/plume_strokes.json" \
            --hm-apply $mode --analysis.givenFlow use --dump "$S/dump-cachev-$mode"
    done
    steady_run "$S" "plume-example-off" "$S/still.0030.png" "$S/matte.png" "$STROKES/plume_strokes.json" --hm off
    # How fast the renders' texture moves against the cache's projected velocity (v of the cachev runs).
    mkdir -p "$S/tif"
    "$VDBTURB" preview "$cache" --width 256 --out "$S/fr/f.####.exr" -q
    for f in "$S"/fr/f.*.exr; do oiiotool "$f" -d float --compression none -o "$S/tif/$(basename "$f" .exr).tif"; done
    oiiotool "$S/dump-cachev-sequence/v.exr" -d float --compression none -o "$S/tif/v.tif"
    /usr/bin/python3 "$ROOT/bench/animate_pattern_speed.py" "$S/tif" "$S/kymograph.ppm"
    oiiotool "$S/kymograph.ppm" -o "$S/kymograph.png"
}

# The picture of a clone: example frame with the source stroke, R' without and with the clone (x12 around grey), output
# frame 20 without and with it. $1 = directory (runs none/ and clone/ with dumps), $2 = example picture, $3 = source
# polyline, $4 = destination polyline (x,y,x,y,...), $5 = frame of R', $6 = the picture to write.
clone_picture() {
    oiiotool "$2" --ch R,G,B --line:color=1,0.2,0.2 "$3" -d uint8 -o "$1/p1.png"
    oiiotool "$1/dump-none/Rprime.$5.exr" --ch R,G,B --mulc 12 --addc 0.5 --clamp:min=0:max=1 -d uint8 -o "$1/p2.png"
    oiiotool "$1/dump-clone/Rprime.$5.exr" --ch R,G,B --mulc 12 --addc 0.5 --clamp:min=0:max=1 \
        --line:color=1,0.2,0.2 "$4" -d uint8 -o "$1/p3.png"
    oiiotool "$1/none/out.0020.png" --ch R,G,B -o "$1/p4.png"
    oiiotool "$1/clone/out.0020.png" --ch R,G,B --line:color=1,0.2,0.2 "$4" -o "$1/p5.png"
    oiiotool "$1/p1.png" "$1/p2.png" "$1/p3.png" "$1/p4.png" "$1/p5.png" --mosaic:pad=4 5x1 -o "$6"
}

do_clone() {
    C="$WORK/clone"
    cache="$DATA/blender-steady-64/fluid_data_####.vdb"
    rm -rf "$C"
    mkdir -p "$C"
    plume_still "$C"
    sed 's/"speed": "example"/"speed": 2.0/' "$STROKES/plume_strokes.json" > "$C/strokes_2px.json"
    "$VDBTURB" preview "$cache" --frames 130 --width 256 --out "$C/example.####.png" -q
    for c in none clone; do
        if [ $c = clone ]; then extra="--clone-strokes $STROKES/plume_clone.json"; else extra=""; fi
        # shellcheck disable=SC2086
        "$VDBTURB" animate --example-cache "$cache" --camera front --width 256 --target "$C/still.0030.png" \
            --target-alpha "$C/matte.png" --flow-strokes "$C/strokes_2px.json" --tau 16 --hm-apply sequence $extra \
            --out "$C/$c/out.####.png" --dump "$C/dump-$c" --measure --json > "$C/$c.jsonl"
        printf 'plume %s: ' "$c"
        tail -1 "$C/$c.jsonl"
    done
    clone_picture "$C" "$C/example.0130.png" 141,210,141,45 128,236,126,150,123,70 0030 "$C/clone-plume.png"
    R="$C/river"
    "$VDBTURB" animate --export-builtin "$R/in" --example builtin:river:320x240x60 --target builtin:river:320x240 -q
    for c in none clone; do
        if [ $c = clone ]; then extra="--clone-strokes $STROKES/river_clone.json"; else extra=""; fi
        # shellcheck disable=SC2086
        "$VDBTURB" animate --example "$R/in/river.####.png" --target "$R/in/still.png" --target-alpha "$R/in/matte.png" \
            --flow-strokes "$STROKES/river_strokes.json" $extra --out "$R/$c/out.####.png" --dump "$R/dump-$c" \
            --measure --json > "$R/$c.jsonl"
        printf 'river %s: ' "$c"
        tail -1 "$R/$c.jsonl"
    done
    clone_picture "$R" "$R/in/river.0030.png" 16,120,304,120 \
        16,137.2,50,146.7,94,147.5,138,135.6,182,116.6,226,99.2,270,91.3,304,94.4 0030 "$C/clone-river.png"
}

do_modes() {
    M="$WORK/modes"
    rm -rf "$M"
    "$VDBTURB" animate --export-builtin "$M/in" --example builtin:river:320x240x60 --target builtin:river:320x240 -q
    for mode in "steerable --hm-rep 3" "steerable --hm-rep 1" "laplacian" "off"; do
        tag=$(echo "$mode" | tr -d ' -')
        # shellcheck disable=SC2086
        "$VDBTURB" animate --example "$M/in/river.####.png" --target "$M/in/still.png" --target-alpha "$M/in/matte.png" \
            --flow-strokes "$STROKES/river_strokes.json" --hm $mode --out "$M/$tag/o.####.png" --measure --json > "$M/$tag.jsonl"
        printf '%s: ' "$mode"
        tail -1 "$M/$tag.jsonl"
    done
}

for what in "$@"; do
    case "$what" in
    sweep) do_sweep ;;
    river) do_river ;;
    plume) do_plume ;;
    stationary) do_stationary ;;
    steady64) do_steady64 ;;
    clone) do_clone ;;
    modes) do_modes ;;
    all) do_sweep; do_river; do_plume; do_stationary; do_steady64; do_clone; do_modes ;;
    *) echo "unknown: $what" >&2; exit 2 ;;
    esac
done
