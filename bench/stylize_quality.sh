#!/bin/sh
# The measurements behind docs/stylize.md: wash-out (uniform vs standard NNF over 160 frames of a
# rotating target), temporal coherence (lambda 0.2 vs 0), boundary IoU, and the Blender plume through a
# camera with a swirl-render exemplar. Writes JSON lines, pictures and plots under WORK; then
#   /usr/bin/python3 bench/stylize_plots.py WORK docs/img
# draws the figures. A measurement, not a test: it never fails on numbers.
#
#   bench/stylize_quality.sh [--vdbturb PATH] [--work DIR] [--frames N] [washout|temporal|plume|all]...
set -eu
NAME=stylize-quality
FRAMES=160
. "$(dirname "$0")/image_bench.sh"

# Wash-out and temporal runs: the three-lobed blob turning 0.03 rad/frame (275 degrees over 160 frames),
# 256x256, the procedural fire exemplar (96 px: a smooth half and a textured half).
washrun() {
    name=$1; shift
    rm -rf "$WORK/$name"
    log "$name: $*"
    "$VDBTURB" stylize --scene rotate --scene-size 256x256 --scene-speed 0.03 --frames "$FRAMES" \
        --exemplar builtin:fire:96 --out "$WORK/$name/o.####.png" --json -q "$@" > "$WORK/$name.jsonl"
}

washout() {
    washrun uniform
    washrun standard --nnf standard
}

temporal() {
    washrun uniform-lambda0 --lambda 0
    washrun standard-lambda0 --nnf standard --lambda 0
}

plume() {
    # The exemplar: the built-in swirl simulated at 48x48x72, its frame 40 rendered from the front and
    # colour-ramped (inferno) on its luminance; alpha = its rendered opacity through the same camera.
    sw="$WORK/swirl"
    if [ ! -f "$sw/swirl.0040.vdb" ]; then
        log "swirl: simulating"
        "$VDBTURB" sim swirl --res 48x48x72 --frames 40 --seed 3 --out "$sw/swirl.####.vdb" -q
    fi
    # --no-crop: the whole domain, as the stylize camera below sees it (the exemplar and its alpha must match)
    "$VDBTURB" preview "$sw/swirl.0040.vdb" --frames 40 --no-crop --out "$sw/render.png" --width 144 -q
    rm -rf "$sw/t"
    "$VDBTURB" stylize --cache "$sw/swirl.####.vdb" --frames 40 --camera front --width 144 --exemplar builtin:fire:32 \
        --out "$sw/t/unused.####.png" --write-target "$sw/t" -q
    oiiotool "$sw/render.png" --ch R,G,B --chsum:weight=0.2126,0.7152,0.0722 --contrast:black=0.08:white=0.85 --colormap inferno \
        -o "$sw/exemplar.png"
    rm -rf "$WORK/plume"
    log "plume: stylizing blender-plume2-128 through the front camera"
    "$VDBTURB" stylize --cache "$DATA/blender-plume2-128/fluid_data_####.vdb" --camera front --width 256 \
        --exemplar "$sw/exemplar.png" --exemplar-alpha "$sw/t/alpha.0040.png" --out "$WORK/plume/o.####.exr" \
        --preview "$WORK/plume/preview" --json -q > "$WORK/plume.jsonl"
    log "plume: perspective camera, frames 25-30"
    "$VDBTURB" stylize --cache "$DATA/blender-plume2-128/fluid_data_####.vdb" --frames 25-30 --camera perspective \
        --camera-pos 4.5,-5,3.2 --look-at 2,2,1.6 --fov 35 --width 256 --exemplar "$sw/exemplar.png" \
        --exemplar-alpha "$sw/t/alpha.0040.png" --out "$WORK/plume-persp/o.####.exr" --preview "$WORK/plume-persp/preview" \
        --json -q > "$WORK/plume-persp.jsonl"
}

for what in "$@"; do
    case "$what" in
    washout) washout ;;
    temporal) temporal ;;
    plume) plume ;;
    all) washout; temporal; plume ;;
    *) echo "unknown: $what" >&2; exit 2 ;;
    esac
done
log "done: $WORK"
