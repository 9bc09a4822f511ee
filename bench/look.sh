#!/bin/sh
# The look of `transfer` against its anchors (issue 42): Blender's own noise up-res of the same target and
# Blender's own simulation of the same scene at the output's resolution, side by side in numbers and pictures.
#
#   bench/look.sh [--work DIR] [--vdbturb PATH] [--pairs "cube paper steady"] [--name NAME] [-- TRANSFER ARGS]
#
# Pairs (anchors baked by Blender 3.4 on first use under WORK; the script skips without `blender`):
#   cube    ../shared/data/blender-plume2-32 -> blender-plume2-128 (x4); anchors: bench/blender/cube_noise.py
#           (Noise x4 of the same 32^3 sim, bit-identical base) and the shared 128^3 sim itself;
#   paper   the paper's configuration (x8): bench/blender/plume.py at 16x16x24 -> the two-jet swirl at 128x128x192
#           (bench/blender_pairs.sh); anchors: plume_noise.py (Noise x8) and plume.py at 128x128x192;
#   steady  blender-steady-64 down-sampled x4 (frames 91-120) -> itself; anchors: steady_noise.py (Noise x4 of
#           Blender's own 16^3 sim of the scene: not the down-sampled grid) and blender-steady-64 itself.
# For each pair: transfer (defaults, or the ARGS after --) into WORK/look/NAME/PAIR, `measure` of it, of the
# noise (density only) and of the high-res sim, each against its own target and with the source; sheets
# WORK/look/NAME/PAIR-{density,vorticity}.png (target | noise | high-res | vdbturb at four frames); the table of
# bench/look_table.py (worst and median per number, against the issue's goals) on stdout.
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
WORK="${VDBTURB_BENCH_WORK:-${TMPDIR:-/tmp}/vdbturb-bench}"
VDBTURB="${VDBTURB:-$ROOT/build/tools/vdbturb}"
DATA="${VDBTURB_SHARED_DATA:-$ROOT/../shared/data}"
PAIRS="cube paper steady"
NAME=defaults
BLENDER=${BLENDER:-blender}
while [ $# -gt 0 ]; do
    case "$1" in
    --work) WORK=$2; shift 2 ;;
    --vdbturb) VDBTURB=$2; shift 2 ;;
    --pairs) PAIRS=$2; shift 2 ;;
    --name) NAME=$2; shift 2 ;;
    --) shift; break ;;
    -h|--help) sed -n "2,19p" "$0" | sed "s/^# \{0,1\}//"; exit 0 ;;
    *) echo "look: unknown argument $1" >&2; exit 2 ;;
    esac
done
. "$ROOT/bench/blender_bake.sh"
require_blender look
OUT="$WORK/look/$NAME"
mkdir -p "$OUT" "$WORK/blender-noise" "$WORK/blender-hires"

for pair in $PAIRS; do
    case $pair in
    cube)
        blender_bake "$WORK/blender-noise/cube" noise/fluid_noise_0030.vdb cube_noise.py "$WORK/blender-noise/cube" 30 4 32
        target="$DATA/blender-plume2-32/fluid_data_####.vdb"
        source="$DATA/blender-plume2-128/fluid_data_####.vdb"
        noise="$WORK/blender-noise/cube/noise/fluid_noise_####.vdb"
        noisebase="$WORK/blender-noise/cube/data/fluid_data_####.vdb"
        hires="$source"; frames=1-30; shown=1,5,15,30 ;;
    paper)
        blender_bake "$WORK/blender-noise/paper" noise/fluid_noise_0030.vdb plume_noise.py "$WORK/blender-noise/paper" 30 8 24
        blender_bake "$WORK/blender-hires/paper" data/fluid_data_0030.vdb plume.py 192 "$WORK/blender-hires/paper" 30
        swirl=$(VDBTURB_BENCH_WORK="$WORK" "$ROOT/bench/blender_pairs.sh" | awk '/^swirl/ { print $2 }')
        target="$WORK/blender-noise/paper/data/fluid_data_####.vdb"
        source="$swirl/data/fluid_data_####.vdb"
        noise="$WORK/blender-noise/paper/noise/fluid_noise_####.vdb"
        noisebase="$target"
        hires="$WORK/blender-hires/paper/data/fluid_data_####.vdb"; frames=1-30; shown=1,5,15,30 ;;
    steady)
        blender_bake "$WORK/blender-noise/steady" noise/fluid_noise_0120.vdb steady_noise.py 16 "$WORK/blender-noise/steady" 120 4
        hires="$DATA/blender-steady-64/fluid_data_####.vdb"
        target="$WORK/look/steady16/fluid_data_####.vdb"
        [ -f "$WORK/look/steady16/fluid_data_0120.vdb" ] ||
            "$VDBTURB" resample "$hires" --down 4 --frames 91-120 --out "$target" -q
        source="$hires"
        noise="$WORK/blender-noise/steady/noise/fluid_noise_####.vdb"
        noisebase="$WORK/blender-noise/steady/data/fluid_data_####.vdb"; frames=91-120; shown=91,95,105,120 ;;
    *) echo "look: unknown pair $pair" >&2; exit 2 ;;
    esac
    dir="$OUT/$pair"
    rm -rf "$dir"
    "$VDBTURB" transfer --target "$target" --source "$source" --out "$dir/out.####.vdb" --frames "$frames" \
        --json -q "$@" > "$OUT/$pair.transfer.json"
    "$VDBTURB" measure --output "$dir/out.####.vdb" --target "$target" --source "$source" -q > "$OUT/$pair.vdbturb.json"
    "$VDBTURB" measure --output "$noise" --target "$noisebase" --source "$source" --frames "$frames" -q \
        > "$OUT/$pair.noise.json"
    "$VDBTURB" measure --output "$hires" --target "$target" --source "$source" --frames "$frames" -q \
        > "$OUT/$pair.hires.json"
    for mode in density vorticity; do
        "$VDBTURB" preview --mode $mode --frames "$shown" --width 220 --match-density --sheet "$OUT/$pair-$mode.png" -q \
            target="$target" "Blender noise=$noise" "Blender high-res=$hires" vdbturb="$dir/out.####.vdb"
    done
    /usr/bin/env python3 "$ROOT/bench/look_table.py" "$pair" "$OUT/$pair"
done
