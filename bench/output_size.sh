#!/bin/sh
# Output size of transfer's default frames against Blender's own noise up-res of the same target (issue 45),
# and how far the written precision moves `measure` (the defaults against --full-float --velocity-margin -1).
#
#   bench/output_size.sh [--work DIR] [--vdbturb PATH] [--pairs "cube paper"]
#
# Pairs (each baked by Blender 3.4 on first use, in WORK/blender-noise/NAME; skipped without `blender`):
#   cube   the shared blender-plume2 scene (bench/blender/cube_noise.py): 32^3 target, its Noise x4, and the
#          shared blender-plume2-128 cache as the source;
#   paper  the paper's 3D configuration (bench/blender/plume_noise.py): the 16x16x24 plume, its Noise x8, and
#          the 128x128x192 two-jet swirl (bench/blender_pairs.sh) as the source.
# Variants: default; full (--full-float --velocity-margin -1: the reference for measure); scale2
# (--vel-voxel-scale 2); novel (--no-velocity). Prints per pair and variant the per-frame size over Blender's noise
# file (median, worst, frames over 2x), the worst frame's bytes per grid (with /usr/bin/python3's pyopenvdb), and
# the relative change of each measure number against full (medians, and the frames that moved over 1%).
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
WORK="${VDBTURB_BENCH_WORK:-${TMPDIR:-/tmp}/vdbturb-bench}"
VDBTURB="${VDBTURB:-$ROOT/build/tools/vdbturb}"
PAIRS="cube paper"
BLENDER=${BLENDER:-blender}
while [ $# -gt 0 ]; do
    case "$1" in
    --work) WORK=$2; shift 2 ;;
    --vdbturb) VDBTURB=$2; shift 2 ;;
    --pairs) PAIRS=$2; shift 2 ;;
    -h|--help) sed -n "2,15p" "$0" | sed "s/^# \{0,1\}//"; exit 0 ;;
    *) echo "output_size: unknown argument $1" >&2; exit 2 ;;
    esac
done
. "$ROOT/bench/blender_bake.sh"
require_blender output_size
mkdir -p "$WORK/blender-noise"

# noise_bake NAME SCRIPT ARGS...: Blender's noise up-res with its base sim, in WORK/blender-noise/NAME.
noise_bake() {
    name=$1; script=$2; shift 2
    blender_bake "$WORK/blender-noise/$name" noise/fluid_noise_0030.vdb "$script" "$WORK/blender-noise/$name" "$@"
}

for pair in $PAIRS; do
    case $pair in
    cube)
        noise_bake cube cube_noise.py 30 4 32
        target="$WORK/blender-noise/cube/data/fluid_data_####.vdb"
        source="$ROOT/../shared/data/blender-plume2-128/fluid_data_####.vdb" ;;
    paper)
        noise_bake paper plume_noise.py 30 8 24
        target="$WORK/blender-noise/paper/data/fluid_data_####.vdb"
        swirl=$(VDBTURB_BENCH_WORK="$WORK" "$ROOT/bench/blender_pairs.sh" | awk '/^swirl/ { print $2 }')
        source="$swirl/data/fluid_data_####.vdb" ;;
    *) echo "output_size: unknown pair $pair" >&2; exit 2 ;;
    esac
    noise="$WORK/blender-noise/$pair/noise/fluid_noise_%04d.vdb"
    out="$WORK/output_size/$pair"
    rm -rf "$out"
    for variant in full default scale2 novel; do
        case $variant in
        default) opts="" ;;
        full) opts="--full-float --velocity-margin -1" ;;
        scale2) opts="--vel-voxel-scale 2" ;;
        novel) opts="--no-velocity" ;;
        esac
        # shellcheck disable=SC2086
        "$VDBTURB" transfer -q --target "$target" --source "$source" --out "$out/$variant/o.####.vdb" $opts
        # Without velocity there is nothing for measure to read.
        [ "$variant" = novel ] && continue
        "$VDBTURB" measure --output "$out/$variant/o.####.vdb" --target "$target" --source "$source" \
            > "$out/$variant.measure" 2>/dev/null
    done
    echo "== $pair: $target -> $source"
    python3 "$ROOT/bench/output_size.py" "$noise" "$out/full" "$out/full.measure" "$out/default" "$out/default.measure" \
        "$out/scale2" "$out/scale2.measure" "$out/novel" -
done
