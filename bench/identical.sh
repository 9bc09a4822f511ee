#!/bin/sh
# Restructuring guard: runs a fixed set of small commands that cover every command and the main
# options of transfer and synth, and records a fingerprint of everything they write: `vdbturb info --checksum`
# for VDB files (grid values bit for bit, metadata apart), md5 for images and text, JSON lines with the timing
# and path fields taken out. Run it before and after a change and compare the two records:
#
#   bench/identical.sh --work /tmp/ident record before.txt     # with the old build
#   bench/identical.sh --work /tmp/ident record after.txt      # with the new build, same --work
#   diff before.txt after.txt                                   # empty: every output is bit-identical
#
# Paths under --work are recorded relative to it, so records made in different work directories compare, but
# for pictures that draw a path (measure's metrics.png title): compare those from the same --work. When the
# fingerprint itself changes, fingerprint both records with the same build: --fingerprint-with NEW_EXE.
set -eu
cd "$(dirname "$0")/.."
WORK="${TMPDIR:-/tmp}/vdbturb-identical"
BIN=build/tools/vdbturb
CHECK=""
while [ $# -gt 0 ]; do
  case "$1" in
    --work) WORK="$2"; shift 2 ;;
    --vdbturb) BIN="$2"; shift 2 ;;
    --fingerprint-with) CHECK="$2"; shift 2 ;; # the vdbturb whose `info --checksum` fingerprints (default --vdbturb)
    *) break ;;
  esac
done
[ "${1:-}" = record ] && [ -n "${2:-}" ] || { echo "usage: $0 [--work DIR] [--vdbturb EXE] [--fingerprint-with EXE] record OUT.txt" >&2; exit 2; }
CHECK="${CHECK:-$BIN}"
OUT="$2"
DATA=../shared/data
mkdir -p "$WORK"
rm -rf "$WORK/run"
mkdir -p "$WORK/run" "$WORK/in"
R="$WORK/run"
: > "$OUT.log"

# A JSON line without what changes from run to run (times, memory, paths of temporaries).
strip_json() { /usr/bin/python3 bench/strip_timing.py; }
step() { # NAME ARGS...: runs vdbturb, keeps its stdout (JSON stripped) and exit code
  name="$1"; shift
  set +e
  "$BIN" "$@" > "$R/$name.stdout" 2>> "$OUT.log"
  code=$?
  set -e
  echo "== $name exit $code" >> "$OUT"
  # A dry run's memory line names what this process may use now (MemAvailable): that changes from run to run.
  strip_json < "$R/$name.stdout" | sed -e "s|$WORK/||g" -e 's/this process may use [^(]*(/this process may use N (/' |
    md5sum | sed "s/-\$/stdout/" >> "$OUT"
}
fingerprint() { # DIR: every file under it
  find "$1" -type f | LC_ALL=C sort | while read -r f; do
    rel="${f#"$WORK"/}"
    case "$f" in
      *.vdb) echo "$rel"; "$CHECK" info "$f" --checksum --headers-only 2>/dev/null | sed -n -e "s|$WORK/||g" -e '/active voxels/,$p' ;;
      *.stdout) ;; # kept, stripped, by step
      # Pixels only: the header holds a DateTime, and --dumpdata's first line the path.
      *.exr) echo "$rel $(oiiotool --dumpdata "$f" | tail -n +2 | md5sum | cut -c1-32)" ;;
      *.json|*.txt|*.jsonl) echo "$rel $(strip_json < "$f" | sed "s|$WORK/||g" | md5sum | cut -c1-32)" ;;
      *.sbatch|*.gp|*.sh) echo "$rel $(sed "s|$WORK/||g" "$f" | md5sum | cut -c1-32)" ;;
      *) echo "$rel $(md5sum < "$f" | cut -c1-32)" ;;
    esac
  done >> "$OUT"
}

: > "$OUT"
# Inputs: the built-in 2D pair and a small 3D pair.
step sim2d_t sim plume --res 24x32x1 --frames 3 --seed 1 --out "$WORK/in/p2/plume.####.vdb" -q
step sim2d_s sim swirl --res 96x128x1 --frames 3 --seed 2 --out "$WORK/in/s2/swirl.####.vdb" -q
step sim3d_t sim plume --res 12x12x16 --frames 3 --seed 1 --out "$WORK/in/p3/plume.####.vdb" -q
step sim3d_s sim swirl --res 48x48x64 --frames 3 --seed 2 --out "$WORK/in/s3/swirl.####.vdb" -q
step sim_obstacle sim obstacle --res 16x16x16 --frames 2 --out "$WORK/in/ob/ob.####.vdb" -q
step sim_ink sim ink --res 48x40 --frames 11 --out "$WORK/in/ink/ink.####.png" -q
fingerprint "$WORK/in"

T=$DATA/blender-plume-32/fluid_data_####.vdb
S=$DATA/blender-plume-128/fluid_data_####.vdb
step tr_default transfer --target "$T" --source "$S" --frames 1-3 --out "$R/tr_default/up.####.vdb" --json -q
step tr_paper transfer --target "$T" --source "$S" --frames 1-2 --temporal-blend 0 --no-seams --density lookback \
  --out "$R/tr_paper/up.####.vdb" --json -q
step tr_small transfer --target "$T" --source "$S" --frames 1-2 --half --velocity-margin 1 --clipping 0.01 \
  --out "$R/tr_small/up.####.vdb" --json -q
step tr_blender transfer --target "$T" --source "$S" --frames 2-3 --style blender --preroll 1 \
  --out "$R/tr_blender/up.####.vdb" --json -q
step tr_knobs transfer --target "$WORK/in/p3/plume.####.vdb" --source "$WORK/in/s3/swirl.####.vdb" --frames 1-3 \
  --align both --coherence 0.1 --no-tracking --detail-energy pasted --density-scheme maccormack --regenerate 0 \
  --whole-fresh-patches --no-target-divergence --out "$R/tr_knobs/up.####.vdb" --json -q
step tr_2d transfer --target "$WORK/in/p2/plume.####.vdb" --source "$WORK/in/s2/swirl.####.vdb" \
  --out "$R/tr_2d/up.####.vdb" --json -q
step tr_resume1 transfer --target "$T" --source "$S" --frames 1-2 --out "$R/tr_resume/up.####.vdb" -q
step tr_resume2 transfer --target "$T" --source "$S" --frames 1-3 --resume --out "$R/tr_resume/up.####.vdb" --json -q
step tr_dry transfer --target "$T" --source "$S" --frames 1-3 --out "$R/tr_dry/up.####.vdb" --dry-run
step me_default measure --target "$T" --source "$S" --output "$R/tr_default/up.####.vdb" --json -q
step me_2d measure --target "$WORK/in/p2/plume.####.vdb" --source "$WORK/in/s2/swirl.####.vdb" \
  --output "$R/tr_2d/up.####.vdb" --json -q --plot "$R/me_plots"

step sy_cache synth --target "$DATA/blender-plume2-32/fluid_data_####.vdb" --frames 1-2 --factor 2 \
  --exemplar swirls:16 --out "$R/sy_cache/s.####.vdb" --json -q
step sy_2d synth --flow vortex --flow-res 16x16x1 --factor 2 --walls x-,x+,y-,y+ --project --frames 2 \
  --out "$R/sy_2d/s.####.vdb" --json -q
step sy_scene synth --scene plume --scene-res 12x8x16 --frames 2 --factor 2 --out "$R/sy_scene/s.####.vdb" --json -q
step sy_paper synth --flow vortex --flow-res 8x8x4 --factor 2 --frames 1 --keep-coarse --detail-everywhere \
  --out "$R/sy_paper/s.####.vdb" --json -q

step pv_sheet preview "target=$T" "output=$R/tr_default/up.####.vdb" --mode density,vorticity,speed,lic --frames 1-3 \
  --width 96 --sheet "$R/pv/sheet.png" -q
step pv_exr preview "$R/tr_2d/up.####.vdb" --mode density --width 64 --out "$R/pv_exr/p.####.exr" -q
step rs_down resample "$DATA/blender-c42/fluid_data_0001.vdb" --frames 1 --down 2 --out "$R/rs/c42.vdb" -q
step rs_rot resample "$S" --frames 1-2 --rotate y:1 --out "$R/rs_rot/r.####.vdb" -q
step info_json info "$T" --json
step st_2d stylize --method lazyfluids --scene rotate --scene-size 48x48 --frames 3 --exemplar builtin:fire:32 \
  --out "$R/st/s.####.png" --json -q
step st_cache stylize --cache "$DATA/blender-plume2-32/fluid_data_####.vdb" --frames 20-21 --camera side --width 48 \
  --exemplar builtin:fire:32 --out "$R/st_cache/c.####.png" --json -q
step fl_ink stylize --method fluidymation --exemplar "$WORK/in/ink/ink.####.png" \
  --exemplar-mask "$WORK/in/ink/ink_mask.####.png" --scene rotate --scene-size 40x40 --frames 3 --b 8 \
  --out "$R/fl/s.####.png" --out-rot "$R/fl/rot.####.exr" --json -q
step an_export animate --export-builtin "$R/an_in" --example builtin:river:48x40x20 --target builtin:river:48x40
step an_run animate --example "$R/an_in/river.####.png" --target "$R/an_in/still.png" \
  --flow-strokes scenes/animate/river_strokes.json --out "$R/an/a.####.exr" --json -q
step farm_plan farm plan --vdbturb vdbturb --chunks 2 --overlap 2 --preroll 2 --dir "$R/farm" --target "$T" --source "$S" --frames 1-10 \
  --out "$R/farm_out/up.####.vdb" -- --patch 8
fingerprint "$R"
echo "recorded $(grep -c '^== ' "$OUT") commands into $OUT (stderr in $OUT.log)"
