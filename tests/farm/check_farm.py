#!/usr/bin/env python3
"""Checks a joined farm output against a sequential run of the same transfer.

usage: check_farm.py PLAN_JSON SEQ_DIR JOINED_DIR SEQ_MEASURE JOINED_MEASURE [--tcoh-factor F] [--hf LO HI] [--strict]

- every frame of the plan exists in the joined output;
- the frames chunk 0 owns alone are byte-identical to the sequential run's (chunk 0 has no pre-roll);
- each seam frame's tcoh (overlap frames and the frame after) <= F x sqrt(median^2 + chord^2), the sequential
  run's median tcoh and the cross-fade's step (below); with --strict also <= 1.1 x median, the issue's target;
- hf_ratio within [LO, HI] on every joined frame from the third on (the first frames of a plume are below the
  band in the sequential run too, see docs/transfer.md; they come from chunk 0, identical to it).
Prints one line per check and the figures; exits 1 on any failure.
"""
import json, math, os, statistics, sys

from farm_results import frames_of, measure

def main(argv):
    plan_path, seq_dir, joined_dir, seq_m, joined_m = argv[1:6]
    factor, lo, hi, strict = 1.1, 0.8, 1.25, False
    rest = argv[6:]
    while rest:
        if rest[0] == "--tcoh-factor":
            factor = float(rest[1]); rest = rest[2:]
        elif rest[0] == "--strict":
            strict = True; rest = rest[1:]
        elif rest[0] == "--hf":
            lo, hi = float(rest[1]), float(rest[2]); rest = rest[3:]
        else:
            sys.exit("unknown argument " + rest[0])
    plan = json.load(open(plan_path))
    frames = frames_of(plan["frames"])
    name = os.path.basename(plan["out"])
    def path(d, f):
        i = name.index("#"); n = name.count("#")
        return os.path.join(d, name[:i] + str(f).zfill(n) + name[i + n:])
    ok = True
    # The JSON plan is the interface for other schedulers (docs/farm.md): N chunk tasks with argv commands, a join
    # that depends on all of them, and every overlap frame listed with weights w_a^2 + w_b^2 = 1.
    chunks = [t for t in plan["tasks"] if t["name"].startswith("chunk")]
    join = [t for t in plan["tasks"] if t["name"] == "join"]
    good = (len(chunks) == plan["chunks"] and len(join) == 1 and sorted(join[0]["depends_on"]) == sorted(t["name"] for t in chunks)
            and all(isinstance(t["command"], list) and "--resume" in t["command"] and t["depends_on"] == [] for t in chunks)
            and len(plan["overlaps"]) == (plan["chunks"] - 1) * plan["overlap"]
            and all(abs(o["detail_a"] ** 2 + o["detail_b"] ** 2 - 1) < 1e-9 and abs(o["density_a"] + o["density_b"] - 1) < 1e-9
                    for o in plan["overlaps"]))
    print("plan.json: %d chunk tasks, join after %s, %d overlap frames: %s" % (len(chunks), join[0]["depends_on"] if join else None,
          len(plan["overlaps"]), "ok" if good else "FAIL"))
    ok &= good
    missing = [f for f in frames if not os.path.exists(path(joined_dir, f))]
    print("frames present: %d/%d%s" % (len(frames) - len(missing), len(frames), " missing %s" % missing if missing else ""))
    ok &= not missing
    overlap = sorted(o["frame"] for o in plan["overlaps"])
    first_blend = overlap[0] if overlap else frames[-1] + 1
    chunk0 = [t for t in plan["tasks"] if t["name"] == "chunk0"][0]
    own0 = [f for f in frames_of(chunk0["frames_kept"]) if f < first_blend]
    # OpenVDB writes a fresh random UUID into every file's header (36 characters at byte 21): all else must match.
    def content(p):
        b = open(p, "rb").read()
        return b[:21] + b[57:]
    same = [f for f in own0 if content(path(seq_dir, f)) == content(path(joined_dir, f))]
    print("chunk 0 frames bit-identical to the sequential run (all bytes but the file UUID): %d/%d" % (len(same), len(own0)))
    ok &= len(same) == len(own0) and len(own0) > 0
    sm, jm = measure(seq_m), measure(joined_m)
    seq_tcoh = [sm[f]["tcoh"] for f in frames[1:] if f in sm and sm[f].get("tcoh") is not None]
    med = statistics.median(seq_tcoh)
    print("sequential median tcoh %.4f" % med)
    # The cross-fade moves the detail from chunk a's to chunk b's along a quarter circle in O + 1 equal steps (the
    # overlap frames and the first frame after it): each step adds a change of chord = 2 sin(pi / (4 (O + 1))) of
    # the detail's rms on top of its own (for independent details). The check: no seam frame's tcoh exceeds
    # factor x sqrt(median^2 + chord^2). The issue's target (tcoh <= 1.1 x median) needs chord << median, that is
    # O of about 3.4 / median frames; it is reported, and enforced with --strict.
    O = plan["overlap"]
    chord = 2 * math.sin(math.pi / (4 * (O + 1))) if O > 0 else 2 ** 0.5
    limit = factor * math.sqrt(med * med + chord * chord)
    print("cross-fade step %.4f; limit on seam frames %.4f" % (chord, limit))
    seam = []
    for f in overlap:
        seam.append(f)
        nxt = f + (frames[1] - frames[0])
        if nxt not in overlap and nxt in jm:
            seam.append(nxt)
    issue_met = True
    same_frame = []
    for f in seam:
        t = jm[f]["tcoh"]
        good = t is not None and t <= limit
        issue_met &= t is not None and t <= 1.1 * med
        st = sm[f]["tcoh"]
        if t is not None and st:
            same_frame.append(t / st)
        print("  seam frame %d%s: tcoh %.4f (sequential %.4f), %.2f x median, %.2f x the sequential frame's %s" % (f,
              "" if f in overlap else " (after)", t, st, t / med, t / st if st else float("nan"), "ok" if good else "FAIL"))
        ok &= good
    print("issue target tcoh <= 1.1 x median on seam frames: %s" % ("met" if issue_met else "NOT met"))
    seq_over = [f for f in seam if sm[f]["tcoh"] is not None and sm[f]["tcoh"] > 1.1 * med]
    if seq_over:
        print("  (the sequential run itself is over 1.1 x its median on %d of these %d frames: %s)" % (len(seq_over),
              len(seam), seq_over))
    if same_frame:
        print("seam tcoh over the sequential run's same frame: %.2f-%.2f, median %.2f" % (min(same_frame),
              max(same_frame), statistics.median(same_frame)))
    if strict:
        ok &= issue_met
    bad = []
    # Frames the joined measure left out (a --frames subset) are listed, not silently passed.
    checked = [f for f in frames[2:] if f in jm]
    for f in checked:
        h = jm[f]["hf_ratio"]
        if not (lo <= h <= hi):
            bad.append((f, h))
    hf = [jm[f]["hf_ratio"] for f in checked]
    print("hf_ratio on %d of frames 3+ (%s): min %.3f max %.3f (band %.2f-%.2f)%s" % (len(checked),
          "all" if len(checked) == len(frames[2:]) else "measured subset", min(hf), max(hf), lo, hi, " out: %s" % bad if bad else ""))
    ok &= not bad
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1

if __name__ == "__main__":
    sys.exit(main(sys.argv))
