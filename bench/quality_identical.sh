#!/bin/sh
# Bit-identity on bench/quality.sh's pairs a and b: the same transfer and measure commands run with an old and a
# new vdbturb, then every output grid fingerprinted (`info --checksum` of the new build) and the JSON compared
# with timings and paths taken out. For restructurings that must not change a single voxel.
#
#   bench/quality_identical.sh OLD_VDBTURB NEW_VDBTURB [WORK]      (RUNS="a b" for some of the runs)
set -eu
[ $# -ge 2 ] || { echo "usage: $0 OLD_VDBTURB NEW_VDBTURB [WORK]" >&2; exit 2; }
OLD=$(readlink -f "$1"); NEW=$(readlink -f "$2")
cd "$(dirname "$0")/.."
W="${3:-${TMPDIR:-/tmp}/vdbturb-quality-identical}"
mkdir -p "$W"
DATA=../shared/data
[ -f "$W/plume16/plume.0012.vdb" ] || "$NEW" sim plume --res 16x16x24 --frames 12 --seed 1 --out "$W/plume16/plume.####.vdb" -q
[ -f "$W/swirl128/swirl.0012.vdb" ] || "$NEW" sim swirl --res 128x128x192 --frames 12 --seed 2 --out "$W/swirl128/swirl.####.vdb" -q
status=0
for run in ${RUNS:-a a-paper a-noseams a-notracking b b-paper}; do
  case $run in
    a*) T="$DATA/blender-plume-32/fluid_data_####.vdb"; S="$DATA/blender-plume-128/fluid_data_####.vdb"; F=1-10 ;;
    b*) T="$W/plume16/plume.####.vdb"; S="$W/swirl128/swirl.####.vdb"; F=1-12 ;;
  esac
  case $run in *-paper) A="--temporal-blend 0" ;; *-noseams) A="--no-seams" ;; *-notracking) A="--no-tracking" ;; *) A="" ;; esac
  for v in old new; do
    B=$OLD; [ $v = new ] && B=$NEW
    o="$W/$run.$v"; rm -rf "$o"
    # shellcheck disable=SC2086
    "$B" transfer --target "$T" --source "$S" --out "$o/up.####.vdb" --frames $F $A --json -q |
      python3 bench/strip_timing.py | sed "s|$o/||g" > "$o.transfer.json"
    "$B" measure --output "$o/up.####.vdb" --target "$T" --source "$S" --frames $F --no-spectra -q |
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
