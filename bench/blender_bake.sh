# Sourced by the benchmarks that bake Blender anchors (bench/look.sh, bench/output_size.sh); the caller sets ROOT
# and BLENDER.
# require_blender NAME: exits 0 with a note when there is no Blender (the benchmark is then skipped, not failed).
require_blender() {
    if ! command -v "$BLENDER" >/dev/null 2>&1; then
        echo "$1: skipped: no '$BLENDER' on PATH (apt-get install blender)" >&2
        exit 0
    fi
}
# blender_bake DIR LAST SCRIPT ARGS...: runs bench/blender/SCRIPT with ARGS in DIR unless DIR/LAST exists (a bake is
# reused). Mantaflow's noise writes its wavelet tile into the working directory, hence the cd.
blender_bake() {
    dir=$1; last=$2; script=$3; shift 3
    if [ ! -f "$dir/$last" ]; then
        rm -rf "$dir"; mkdir -p "$dir"
        echo "baking $dir with $script $* (minutes)" >&2
        (cd "$dir" && "$BLENDER" -b --factory-startup --python "$ROOT/bench/blender/$script" -- "$@" > bake.log 2>&1)
    fi
}
