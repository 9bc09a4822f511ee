#!/bin/sh
# Bit-identity on bench/quality.sh's pairs (bench/pairs.sh: a, b, c, d, side and their variants): the same
# transfer and measure commands run with an old and a new vdbturb, then every output grid fingerprinted
# (`info --checksum` of the new build) and the JSON compared with timings and paths taken out.
# For restructurings that must not change a single voxel.
#
#   bench/quality_identical.sh OLD_VDBTURB NEW_VDBTURB [WORK]      (RUNS="a c side-none" for some of the runs)
set -eu
[ $# -ge 2 ] || { echo "usage: $0 OLD_VDBTURB NEW_VDBTURB [WORK]" >&2; exit 2; }
OLD=$(readlink -f "$1"); NEW=$(readlink -f "$2")
cd "$(dirname "$0")/.."
W="${3:-${TMPDIR:-/tmp}/vdbturb-quality-identical}"
mkdir -p "$W"
BIN=$NEW; WORK=$W; FRAMES=12; DATA=../shared/data
. bench/pairs.sh
status=0
for run in ${RUNS:-a a-paper a-noseams a-notracking b b-paper c d side-none side-rotate}; do
  pair_inputs "$run"
  for v in old new; do
    B=$OLD; [ $v = new ] && B=$NEW
    o="$W/$run.$v"; rm -rf "$o"
    # shellcheck disable=SC2086
    "$B" transfer --target "$T" --source "$S" --out "$o/up.####.vdb" --frames "$F" $ARGS --json -q |
      python3 bench/strip_timing.py | sed "s|$o/||g" > "$o.transfer.json"
    "$B" measure --output "$o/up.####.vdb" --target "$T" --source "$S" --frames "$F" --no-spectra -q |
      python3 bench/strip_timing.py | sed "s|$o/||g" > "$o.measure.json"
    for f in "$o"/up.*.vdb; do "$NEW" info "$f" --checksum --headers-only 2>/dev/null | sed -n -e "s|$o/||g" -e '/active voxels/,$p'; done > "$o.sums"
  done
  r="identical"
  cmp -s "$W/$run.old.sums" "$W/$run.new.sums" || r="GRIDS DIFFER"
  cmp -s "$W/$run.old.measure.json" "$W/$run.new.measure.json" || r="$r; measure JSON differs"
  cmp -s "$W/$run.old.transfer.json" "$W/$run.new.transfer.json" || r="$r; transfer JSON differs"
  [ "$r" = identical ] || status=1
  echo "$run: $(ls "$W/$run.new"/*.vdb | wc -l) frames: $r"
done
exit $status
