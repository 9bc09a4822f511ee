# The common start of bench/stylize_quality.sh and bench/fluidymation_quality.sh. Sourced, not run: the
# caller sets NAME (its log prefix and work folder) and FRAMES (the default frame count), then sources this
# with its own arguments, which it parses: [--vdbturb PATH] [--work DIR] [--frames N] [PART...] (default all).
# Sets ROOT, DATA, VDBTURB, WORK, FRAMES, the remaining arguments and log().
ROOT=$(cd "$(dirname "$0")/.." && pwd)
DATA="$(cd "$ROOT/.." && pwd)/shared/data"
VDBTURB="$ROOT/build/tools/vdbturb"
WORK="${TMPDIR:-/tmp}/vdbturb-$NAME"
while [ $# -gt 0 ]; do
    case "$1" in
    --vdbturb) VDBTURB=$2; shift 2 ;;
    --work) WORK=$2; shift 2 ;;
    --frames) FRAMES=$2; shift 2 ;;
    *) break ;;
    esac
done
[ $# -gt 0 ] || set -- all
mkdir -p "$WORK"
log() { printf '%s: %s\n' "$NAME" "$*" >&2; }
