#!/usr/bin/env python3
"""Checks a space-tiled farm output against an untiled run of the same transfer (docs/farm.md, "Space tiles").

usage: check_tiles.py PLAN_JSON SEQ_MEASURE JOINED_MEASURE [--block MAX] [--lf-tol ABS] [--summary]

SEQ_MEASURE is `measure` of the untiled run with --tile-borders set to the plan's borders (so that its tile_* figures
cover the same voxels); JOINED_MEASURE is `measure` of the joined output (the borders come from its metadata).
- every frame of the plan was measured in both;
- on the smoke within two patches of a tile border: tile_block <= MAX (1.05) and tile_div_rel <= div_rel_source (the
  source's own) on every frame, or, where the untiled run's own tile_div_rel is over it too (a plume's first frame),
  within 0.002 of the untiled run's (the tiles add nothing there; listed in a note);
- lf_err of the joined output within ABS (0.005) of the untiled run's on every frame;
- tile_hf_ratio (the detail's strength near the borders) within 0.8-1.25 times the untiled run's at the same voxels
  (our own check: a seam of weaker detail passes block and div_rel);
- the joined frames carry the plan's borders.
Prints one line per check and a per-frame table; exits 1 on any failure. --summary prints only the summary line.
"""
import json, sys

from farm_results import frames_of, measure

def main(argv):
    plan_path, seq_m, joined_m = argv[1:4]
    block_max, lf_tol, summary = 1.05, 0.005, False
    rest = argv[4:]
    while rest:
        if rest[0] == "--block":
            block_max = float(rest[1]); rest = rest[2:]
        elif rest[0] == "--lf-tol":
            lf_tol = float(rest[1]); rest = rest[2:]
        elif rest[0] == "--summary":
            summary = True; rest = rest[1:]
        else:
            sys.exit("unknown argument " + rest[0])
    plan = json.load(open(plan_path))
    if plan.get("kind") != "space_tiles":
        sys.exit("FAIL: " + plan_path + " is not a space-tile plan")
    frames = frames_of(plan["frames"])
    seq, joined = measure(seq_m), measure(joined_m)
    ok = True
    missing = [f for f in frames if f not in seq or f not in joined]
    if missing:
        print("FAIL: frames not measured:", missing); ok = False
    worst_block, worst_div, worst_lf, tile_voxels = 0.0, -1.0, 0.0, 0
    hf_lo, hf_hi = float("inf"), 0.0
    over_untiled, div_tol = [], 0.002
    if not summary:
        print("frame  tile_voxels  tile_block (untiled)  tile_div_rel (untiled)  div_rel_source  lf_err (untiled)"
              "  tile_hf_ratio (untiled)")
    for f in frames:
        if f in missing:
            continue
        j, s = joined[f], seq[f]
        tb, td, ds = j.get("tile_block"), j.get("tile_div_rel"), j.get("div_rel_source")
        tile_voxels += j.get("tile_voxels", 0)
        if not summary:
            print("%5d  %11d  %s (%s)  %s (%s)  %s  %.4f (%.4f)  %s (%s)" % (f, j.get("tile_voxels", 0), fmt(tb),
                fmt(s.get("tile_block")), fmt(td), fmt(s.get("tile_div_rel")), fmt(ds), j["lf_err"], s["lf_err"],
                fmt(j.get("tile_hf_ratio")), fmt(s.get("tile_hf_ratio"))))
        th, sth = j.get("tile_hf_ratio"), s.get("tile_hf_ratio")
        if th is not None and sth:
            q = th / sth
            hf_lo, hf_hi = min(hf_lo, q), max(hf_hi, q)
            if not 0.8 <= q <= 1.25:
                print("FAIL: frame %d tile_hf_ratio %.3f, %.2fx the untiled run's" % (f, th, q)); ok = False
        if tb is not None:
            worst_block = max(worst_block, tb)
            if tb > block_max:
                print("FAIL: frame %d tile_block %.3f > %.3f" % (f, tb, block_max)); ok = False
        if td is not None and ds is not None:
            worst_div = max(worst_div, td - ds)
            st = s.get("tile_div_rel")
            if td > ds and st is not None and td <= st + div_tol:
                # The untiled run is over the source's here too (a plume's first frame): the tiles add nothing.
                over_untiled.append(f)
            elif td > ds:
                print("FAIL: frame %d tile_div_rel %.4f > the source's div_rel %.4f (untiled %s)" % (f, td, ds, fmt(st)))
                ok = False
        if j["lf_err"] is not None and s["lf_err"] is not None:
            d = abs(j["lf_err"] - s["lf_err"])
            worst_lf = max(worst_lf, d)
            if d > lf_tol:
                print("FAIL: frame %d lf_err %.4f, untiled %.4f" % (f, j["lf_err"], s["lf_err"])); ok = False
    if over_untiled:
        print("note: tile_div_rel over the source's on frames %s, where the untiled run's is too (within %.3f)"
              % (over_untiled, div_tol))
    if tile_voxels == 0:
        print("FAIL: no smoke near a tile border on any frame: the check covers nothing"); ok = False
    print("tiles %s: tile_block max %.3f (<= %.2f), tile_div_rel - div_rel_source max %+.4f (<= 0), "
          "|lf_err - untiled| max %.4f (<= %.3f), tile_hf_ratio %s x the untiled run's: %s"
          % ("x".join(map(str, plan["tiles"]["counts"])), worst_block, block_max, worst_div, worst_lf, lf_tol,
             "%.3f-%.3f" % (hf_lo, hf_hi) if hf_hi > 0 else "-", "ok" if ok else "FAILED"))
    return 0 if ok else 1

def fmt(v):
    return "   -  " if v is None else "%.4f" % v

if __name__ == "__main__":
    sys.exit(main(sys.argv))
