#!/bin/sh
# Runs the libFuzzer targets (tests/fuzz/fuzz_*.cc) one after the other, each for a given time, and prints per
# target the executions, the coverage (libFuzzer's cov: edges and ft: features), the corpus size and the
# crashes found. Needs clang-14 and libfuzzer-14-dev (tools/setup-debian12.sh installs them).
#
#   bench/fuzz.sh                          # every target, 600 s each
#   bench/fuzz.sh --time 60 frame_pattern  # one target, one minute
#   bench/fuzz.sh --build build-fuzz --work /tmp/fuzz vdb_reader
#
# The build folder (default build-fuzz) is configured with CXX=clang++-14 -DVDBTURB_BUILD_FUZZERS=ON when it
# does not exist. Seeds: the VDB caches in ../shared/data (vdb_reader), pattern and frame-list strings
# (frame_pattern), resume states as transfer writes them (resume_state); the growing corpus is kept in
# WORK/corpus/TARGET, crashes in WORK/crashes/TARGET. A crash input belongs in tests/fuzz/crashes/TARGET once
# fixed: ctest replays that folder (fuzz_crashes_TARGET). One target at a time: the machine has 2 cores.
set -eu

here=$(cd "$(dirname "$0")/.." && pwd)
build="$here/build-fuzz"
work="${TMPDIR:-/tmp}/vdbturb-fuzz"
seconds=600
timeout=30
targets=""
while [ $# -gt 0 ]; do
  case "$1" in
    --time) seconds=$2; shift 2 ;;
    --timeout) timeout=$2; shift 2 ;; # seconds one input may take (libFuzzer -timeout); raise it on a busy machine
    --build) build=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    -*) echo "fuzz.sh: unknown option $1" >&2; exit 2 ;;
    *) targets="$targets $1"; shift ;;
  esac
done
[ -n "$targets" ] || targets="vdb_reader frame_pattern resume_state"
data="$here/../shared/data"

if [ ! -f "$build/build.ninja" ]; then
  CC=clang-14 CXX=clang++-14 cmake -S "$here" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
    -DVDBTURB_BUILD_FUZZERS=ON -DVDBTURB_BUILD_TESTS=OFF -DVDBTURB_BUILD_TOOLS=OFF >/dev/null
fi
mkdir -p "$work"
for t in $targets; do
  cmake --build "$build" -j2 --target "fuzz_$t" >"$work/build.log" 2>&1 ||
    { tail -20 "$work/build.log" >&2; echo "fuzz.sh: building fuzz_$t failed (all of it in $work/build.log)" >&2; exit 1; }
done

seed() { # seed TARGET DIR
  mkdir -p "$2"
  case "$1" in
    vdb_reader)
      # Small real caches of every writer: Blender (Mantaflow), Houdini, and the crash inputs kept so far.
      for f in "$data"/blender-plume-32/fluid_data_000[1-5].vdb "$data"/houdini-vel/*.vdb; do
        [ -f "$f" ] && cp "$f" "$2/$(basename "$(dirname "$f")")_$(basename "$f")"
      done ;;
    frame_pattern)
      i=0
      for s in 'cache/pyro.####.vdb' 'a_%04d.vdb' 'x.$F4.vdb' 'x.${F4}.vdb' 'x.@@@.vdb' 'x.$F.vdb' 'x.@.vdb' \
               '1001-1100x2,1200' '-3--1,5' '1-10,12,14-20x2' 'fluid_data_0001.vdb' 'pyro.1001.bgeo.sc' 'smoke.vdb'; do
        i=$((i + 1)); printf '%s' "$s" > "$2/seed$i"
      done ;;
    resume_state)
      printf 'v2 f=4 B=8 rot=-1 tracks=' > "$2/empty"
      printf 'v2 f=4 B=8 rot=-1 tracks=0,0,0,0,0,0;1,0,0,8,0,0;0,1,0,0,8,0' > "$2/tracks"
      printf 'v2 f=4 B=8 rot=5 tracks=1,1,1,16,16,16;2,1,1,24,16,16' > "$2/rotated" ;;
  esac
  [ -d "$here/tests/fuzz/crashes/$1" ] && cp "$here/tests/fuzz/crashes/$1"/* "$2/" 2>/dev/null || true
}

printf '%-14s %8s %12s %8s %8s %8s %8s\n' target seconds executions cov ft corpus crashes
for t in $targets; do
  corpus="$work/corpus/$t"; seeds="$work/seeds/$t"; crashes="$work/crashes/$t"
  rm -rf "$seeds"; seed "$t" "$seeds"; mkdir -p "$corpus" "$crashes"
  log="$work/$t.log"
  # A plain run stops at the first crash. -malloc_limit_mb is lifted because the guarded reader's forked child
  # inherits libFuzzer's malloc hooks: a damaged size field there is the child's (bounded) problem, not a finding.
  VDBTURB_FUZZ_DIR="$work" "$build/tests/fuzz/fuzz_$t" "$corpus" "$seeds" -max_total_time="$seconds" \
    -timeout="$timeout" -rss_limit_mb=4096 -malloc_limit_mb=1000000 -max_len=400000 -print_final_stats=1 -artifact_prefix="$crashes/" >"$log" 2>&1 || true
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  ft=$(grep -o 'ft: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  n=$(ls "$corpus" | wc -l)
  # Findings: crash-, leak-, timeout- and oom- files; slow-unit- files are only inputs slower than 10 s.
  c=$(ls "$crashes" | grep -c -E '^(crash|leak|timeout|oom)-' || true)
  printf '%-14s %8s %12s %8s %8s %8s %8s\n' "$t" "$seconds" "${execs:-?}" "${cov:-?}" "${ft:-?}" "$n" "$c"
done
echo "logs and crash inputs: $work"
