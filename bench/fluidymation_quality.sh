#!/bin/sh
# The measurements behind the Fluidymation section of docs/stylize.md: the ablations (each weight set to
# 0) on two built-in targets, and the Blender plume through a camera. Writes JSON lines, frames and
# previews under WORK; then
#   /usr/bin/python3 bench/fluidymation_plots.py WORK docs/img
# prints the tables and draws the figures. A measurement, not a test: it never fails on numbers.
#
#   bench/fluidymation_quality.sh [--vdbturb PATH] [--work DIR] [--frames N] [ablation|plume|exemplar|all]...
set -eu
NAME=fluidymation-quality
FRAMES=30
. "$(dirname "$0")/image_bench.sh"

# One run: NAME, then the target's and the variant's options. The exemplar is builtin:ink (320x240,
# 30 frames: a drop spreading on wet paper).
run() {
    name=$1; shift
    rm -rf "${WORK:?}/$name"
    log "$name: $*"
    "$VDBTURB" stylize --method fluidymation --exemplar builtin:ink --out "$WORK/$name/o.####.png" --preview "$WORK/$name/preview" \
        --json -q "$@" > "$WORK/$name.jsonl"
}

# grow: a blot spreading (uniform dilation, 1.9 px/frame at the rim) that comes to rest at frame 27;
# stroke: a brush stroke whose tip advances 5.8 px/frame while the painted body rests.
ablation() {
    for target in grow stroke; do
        case $target in
        grow) t="--scene grow --scene-size 320x320 --scene-speed 0.006 --frames $FRAMES" ;;
        stroke) t="--scene stroke --scene-size 480x240 --scene-speed 0.012 --frames $FRAMES" ;;
        esac
        # shellcheck disable=SC2086
        run "$target-default" $t
        for w in dir ext temp uni bound; do
            # shellcheck disable=SC2086
            run "$target-$w"0 $t --w-$w 0
        done
    done
}

# The Blender plume (128^3, 30 frames) through the front camera at 384 px: the mask is the rendered
# opacity >= 0.5, the flow the opacity-weighted projected velocity. Table 1's b = 30 px and b = 10
# (b scaled to this resolution), and w^temp = 0 for the flicker comparison.
plume() {
    c="--cache $DATA/blender-plume2-128/fluid_data_####.vdb --camera front --width 384"
    # shellcheck disable=SC2086
    run plume-default $c
    # shellcheck disable=SC2086
    run plume-b10 $c --b 10
    # shellcheck disable=SC2086
    run plume-b10-temp0 $c --b 10 --w-temp 0
    # shellcheck disable=SC2086
    run plume-b10-side --cache "$DATA/blender-plume2-128/fluid_data_####.vdb" --camera side --width 384 --b 10
}

# The exemplar itself on disk (frames, masks, flows), for the figures.
exemplar() {
    rm -rf "$WORK/ink"
    "$VDBTURB" sim ink --frames 30 --out "$WORK/ink/ink.####.png" -q
}

for what in "$@"; do
    case "$what" in
    ablation) ablation ;;
    plume) plume ;;
    exemplar) exemplar ;;
    all) exemplar; ablation; plume ;;
    *) echo "unknown: $what" >&2; exit 2 ;;
    esac
done
log "done: $WORK"
