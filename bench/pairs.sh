# The pairs and variants of bench/quality.sh, shared with bench/quality_identical.sh. Sourced, not run; the
# caller sets BIN (the vdbturb that prepares the built-in pairs), WORK, FRAMES and DATA.
# pair_inputs RUN sets T (target pattern), S (source pattern), F (frame range), ARGS and WHAT, preparing the
# built-in and resampled inputs under WORK on first use.

prepare_b() {
  t="$WORK/plume16"; s="$WORK/swirl128"
  [ -f "$t/plume.$(printf %04d "$FRAMES").vdb" ] || "$BIN" sim plume --res 16x16x24 --frames "$FRAMES" --seed 1 --out "$t/plume.####.vdb" -q
  [ -f "$s/swirl.$(printf %04d "$FRAMES").vdb" ] || "$BIN" sim swirl --res 128x128x192 --frames "$FRAMES" --seed 2 --out "$s/swirl.####.vdb" -q
}
prepare_d() {
  prepare_b
  s="$WORK/swirl100"
  [ -f "$s/swirl.$(printf %04d "$FRAMES").vdb" ] || "$BIN" sim swirl --res 100x100x150 --frames "$FRAMES" --seed 2 --out "$s/swirl.####.vdb" -q
}
prepare_c() {
  [ -f "$WORK/proxy/proxy.0030.vdb" ] || "$BIN" resample "$DATA/blender-plume-128/fluid_data_####.vdb" --down 4 --frames 1-30 --out "$WORK/proxy/proxy.####.vdb" -q
}
prepare_side() {
  [ -f "$WORK/side/side.0010.vdb" ] || "$BIN" resample "$DATA/blender-plume-128/fluid_data_####.vdb" --rotate y:1 --frames 1-10 --out "$WORK/side/side.####.vdb" -q
}

pair_inputs() {
  run=$1
  pair=$(echo "$run" | cut -d- -f1)
  variant=$(echo "$run" | cut -s -d- -f2-)
  case "$pair" in
    a) T="$DATA/blender-plume-32/fluid_data_####.vdb"; S="$DATA/blender-plume-128/fluid_data_####.vdb"; F="1-10" ;;
    b) prepare_b; T="$WORK/plume16/plume.####.vdb"; S="$WORK/swirl128/swirl.####.vdb"; F="1-$FRAMES" ;;
    d) prepare_d; T="$WORK/plume16/plume.####.vdb"; S="$WORK/swirl100/swirl.####.vdb"; F="1-$FRAMES" ;;
    c) prepare_c; T="$WORK/proxy/proxy.####.vdb"; S="$DATA/blender-plume-128/fluid_data_####.vdb"; F="${CFRAMES:-1-30}" ;;
    side) prepare_side; T="$DATA/blender-plume-32/fluid_data_####.vdb"; S="$WORK/side/side.####.vdb"; F="1-10" ;;
    *) echo "pairs: unknown run $run" >&2; exit 2 ;;
  esac
  case "$variant" in
    "") ARGS=""; WHAT="defaults" ;;
    noseams) ARGS="--no-seams"; WHAT="no seam smoothing" ;;
    gamma0) ARGS="--gamma 0"; WHAT="gamma = 0" ;;
    paper) ARGS="--temporal-blend 0"; WHAT="beta 0.5, no temporal blending (the paper)" ;;
    paper-beta0) ARGS="--temporal-blend 0 --beta 0"; WHAT="beta = 0, no temporal blending" ;;
    notracking) ARGS="--no-tracking"; WHAT="global search every frame" ;;
    alpha0) ARGS="--alpha 0"; WHAT="alpha = 0 (velocity alone)" ;;
    alpha1) ARGS="--alpha 1"; WHAT="alpha = 1 (density weighs 250x the paper's)" ;;
    paper-beta5) ARGS="--temporal-blend 0 --beta 5"; WHAT="beta = 5, no temporal blending" ;;
    beta0) ARGS="--beta 0"; WHAT="beta = 0, with temporal blending" ;;
    prev) ARGS="--temporal-blend 0.9 --box-keep 0 --coarse-tolerance 0"; WHAT="earlier defaults: blend 0.9, means to zero" ;;
    exact) ARGS="--coarse-tolerance 0"; WHAT="coarse part removed exactly" ;;
    keep0) ARGS="--box-keep 0"; WHAT="box rows pull the means to zero" ;;
    notd) ARGS="--no-target-divergence"; WHAT="paper's div(U_h) term" ;;
    mu5) ARGS="--value-weight 5"; WHAT="value rows, weight 5" ;;
    whole) ARGS="--whole-fresh-patches"; WHAT="fresh patches solved whole" ;;
    pure) ARGS="--temporal-blend 0.999 --no-seams --coarse-tolerance 1"; WHAT="last frame's detail advected and rescaled, nothing else" ;;
    nocrop) ARGS="--target-no-crop --source-no-crop"; WHAT="whole domains held (the read before the crop)" ;;
    none) ARGS="--align none"; WHAT="sideways source, --align none" ;;
    rotate) ARGS="--align rotate"; WHAT="sideways source, --align rotate" ;;
    *) echo "pairs: unknown variant $variant" >&2; exit 2 ;;
  esac
}
