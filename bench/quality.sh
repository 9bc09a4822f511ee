#!/bin/sh
# Transfer quality on the issue's three pairs, the ablations and the alignment experiment, measured with
# `vdbturb measure`. Prints one markdown table row per run (medians over frames, first frame excluded for
# tcoh by construction; aniso_ratio, lattice and vort_peak_ratio are the structure and hot-spot numbers of
# docs/measure.md) and keeps every JSON line under WORK. POSIX sh + sed only.
#
#   bench/quality.sh [--work DIR] [--frames N] [RUN...]
#
# Runs: a, a-noseams, a-gamma0, a-paper, a-paper-beta0, a-notracking, b, b-noseams, b-gamma0, b-paper,
#       b-paper-beta0, b-notracking, c, d, side-none, side-rotate   (default: all)
#       Also on any pair: -alpha0, -alpha1, -paper-beta5, -beta0 (parameters); for the tcoh study -prev (the
#       defaults before the coarse tolerance), -exact, -keep0, -notd, -mu5, -whole, -pure (see docs/transfer.md);
#       -nocrop holds the whole domains (the read before the crop; docs/design.md).
# Pair a: ../shared/data/blender-plume-32 -> blender-plume-128 (frames 1-10).
# Pair b: built-in plume 16x16x24 -> swirl 128x128x192 (the paper's 3D configuration), N frames (default 12).
# Pair c: target = blender-plume-128 box-downsampled by 4 -> blender-plume-128 (frames 1-30, the whole
#         cache; CFRAMES=1-10 for the first ten only).
# Pair d: pair b with the swirl at 100x100x150: ratio 6.25, the source resampled to ratio 6.
# side-*: target blender-plume-32, source blender-plume-128 turned a quarter turn about y (flow along x).
set -eu
cd "$(dirname "$0")/.."
WORK="${TMPDIR:-/tmp}/vdbturb-quality"
FRAMES=12
while [ $# -gt 0 ]; do
  case "$1" in
    --work) WORK="$2"; shift 2 ;;
    --frames) FRAMES="$2"; shift 2 ;;
    --) shift; break ;;
    -*) echo "quality: unknown option $1" >&2; exit 2 ;;
    *) break ;;
  esac
done
RUNS="${*:-a a-noseams a-gamma0 a-paper a-paper-beta0 a-notracking b b-noseams b-gamma0 b-paper b-paper-beta0 b-notracking c d side-none side-rotate}"
BIN=""
for b in build/tools/vdbturb build*/tools/vdbturb; do [ -x "$b" ] && BIN="$b" && break; done
[ -n "$BIN" ] || { echo "quality: build vdbturb first (tools/build.sh)" >&2; exit 2; }
DATA=../shared/data
mkdir -p "$WORK"
. bench/pairs.sh

# median VALUE of KEY from the measure summary line: "KEY":{...,"median":V,...}
median() { sed -n 's/.*"'"$1"'":{[^}]*"median":\([-0-9.e+]*\).*/\1/p' "$2" | tail -n 1; }
# median over the per-frame lines of a numeric KEY
frame_median() {
  sed -n 's/.*"'"$1"'":\([-0-9.e+]*\).*/\1/p' "$2" | sort -g | awk '{v[NR]=$1} END{if (NR) print (NR%2 ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2)}'
}
fmt() { [ -n "$1" ] && printf '%.3g' "$1" || printf -- '-'; }

echo "| run | what | lf_err | hf_ratio | div_rel (source) | block | tcoh (source) | tcoh floor | aniso_ratio | lattice | vort_peak_ratio | match E_h | energy scale | median s/frame |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
for run in $RUNS; do
  pair_inputs "$run"
  out="$WORK/$run"
  rm -rf "$out"
  # shellcheck disable=SC2086
  "$BIN" transfer --target "$T" --source "$S" --out "$out/up.####.vdb" --frames "$F" $ARGS --json -q > "$WORK/$run.transfer.jsonl"
  "$BIN" measure --output "$out/up.####.vdb" --target "$T" --source "$S" --frames "$F" --no-spectra -q > "$WORK/$run.measure.jsonl"
  m="$WORK/$run.measure.jsonl"
  tj="$WORK/$run.transfer.jsonl"
  sec=$(sed -n 's/.*"median_s_per_frame":\([-0-9.e+]*\).*/\1/p' "$tj" | tail -n 1)
  eh=$(frame_median mean_local_energy "$tj")
  es=$(frame_median energy_scale "$tj")
  # The triangle inequality's floor on tcoh for a frame whose detail grew by g over last frame's, advected.
  fl=$(sed -n 's/.*"detail_growth":\([-0-9.e+]*\).*/\1/p' "$tj" | awk '$1 > 0 {f = 1 - 1 / $1; if (f < 0) f = 0; print f}' | sort -g |
       awk '{v[NR]=$1} END{if (NR) print (NR%2 ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2)}')
  echo "| $run | $WHAT | $(fmt "$(median lf_err "$m")") | $(fmt "$(median hf_ratio "$m")") | $(fmt "$(median div_rel "$m")") ($(fmt "$(median div_rel_source "$m")")) | $(fmt "$(median block "$m")") | $(fmt "$(median tcoh "$m")") ($(fmt "$(median tcoh_source "$m")")) | $(fmt "$fl") | $(fmt "$(median aniso_ratio "$m")") | $(fmt "$(median lattice "$m")") | $(fmt "$(median vort_peak_ratio "$m")") | $(fmt "$eh") | $(fmt "$es") | $(fmt "$sec") |"
done
