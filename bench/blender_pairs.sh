#!/bin/sh
# Bakes the Blender 3.4 Mantaflow caches of the 3D configuration of Sato et al. for the benchmarks
# (bench/run.sh blender-paper3d), with the scene scripts in bench/blender/:
#
#   WORK/blender/plume_16x16x24_fN/data/fluid_data_####.vdb          the low-res target: a buoyant plume
#   WORK/blender/swirl2jet_128x128x192_fN/data/fluid_data_####.vdb   the high-res source: a two-jet swirl
#
# Both in the same 4x4x6 world domain. A bake is reused while its last frame exists and the scene scripts
# have not changed (a checksum is kept next to it); --force bakes again. Without a `blender` on PATH
# (Debian 12: apt-get install blender, Blender 3.4) it says so and exits 0 having done nothing.
#
#   bench/blender_pairs.sh [--work DIR] [--frames N] [--threads N] [--force] [--blender PATH]
#
# Prints, on stdout, one line per bake: NAME DIR, and what each bake took on stderr.
set -eu

ROOT=$(cd "$(dirname "$0")/.." && pwd)
SCENES="$ROOT/bench/blender"
WORK="${VDBTURB_BENCH_WORK:-${TMPDIR:-/tmp}/vdbturb-bench}"
FRAMES=30
THREADS=0
FORCE=0
BLENDER=${BLENDER:-blender}

while [ $# -gt 0 ]; do
    case "$1" in
    --work) WORK=$2; shift 2 ;;
    --frames) FRAMES=$2; shift 2 ;;
    --threads) THREADS=$2; shift 2 ;;
    --force) FORCE=1; shift ;;
    --blender) BLENDER=$2; shift 2 ;;
    -h|--help) sed -n "2,15p" "$0" | sed "s/^# \{0,1\}//"; exit 0 ;;
    *) echo "blender_pairs: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done

log() { printf 'blender_pairs: %s\n' "$*" >&2; }

if ! command -v "$BLENDER" >/dev/null 2>&1; then
    log "skipped: no '$BLENDER' on PATH (Debian 12: apt-get install blender, which is Blender 3.4)"
    exit 0
fi
log "$("$BLENDER" --version 2>/dev/null | head -n 1) at $(command -v "$BLENDER"); work: $WORK"

STAMP=$(cat "$SCENES"/*.py | cksum | cut -d ' ' -f 1)
LAST=$(printf '%04d' "$FRAMES")

# bake NAME SCRIPT RES_Z: bakes WORK/blender/NAME unless a complete bake of the same scripts is there.
bake() {
    name=$1; script=$2; res=$3
    dir="$WORK/blender/$name"
    if [ "$FORCE" = 0 ] && [ -f "$dir/data/fluid_data_$LAST.vdb" ] && [ "$(cat "$dir/scene.cksum" 2>/dev/null)" = "$STAMP" ]; then
        log "$name: reusing $dir"
    else
        rm -rf "$dir"
        mkdir -p "$dir"
        log "$name: baking $FRAMES frames with $script (load average $(cut -d ' ' -f 1-3 /proc/loadavg 2>/dev/null))"
        if ! "$BLENDER" -b --factory-startup -t "$THREADS" --python "$SCENES/$script" -- "$res" "$dir" "$FRAMES" > "$dir/bake.log" 2>&1 \
            || [ ! -f "$dir/data/fluid_data_$LAST.vdb" ]; then
            log "$name: the bake failed; Blender's output is in $dir/bake.log"
            exit 1
        fi
        echo "$STAMP" > "$dir/scene.cksum"
        log "$name: $(grep '"summary"' "$dir/bake.log" | sed 's/.*"total_s": *\([0-9.]*\).*"peak_rss_mb": *\([0-9.]*\).*/\1 \2/' | awk '{ printf "baked in %.1f s, peak RSS %.0f MB", $1, $2 }')"
    fi
    printf '%s %s\n' "$name" "$dir"
}

bake "plume_16x16x24_f$FRAMES" plume.py 24
bake "swirl2jet_128x128x192_f$FRAMES" two_jet_swirl.py 192
