"""Compares transfer outputs' file sizes with Blender's noise files and their measure numbers with a reference run.

    python3 output_size.py NOISE_PATTERN(%04d) REF_DIR REF.measure DIR MEASURE [DIR MEASURE ...]

A MEASURE of '-' compares sizes only. Called by bench/output_size.sh.
"""
import json
import os
import subprocess
import sys

KEYS = ["lf_err", "hf_ratio", "div_rel", "block", "tcoh", "density_err", "mass_ratio", "vort_peak_ratio",
        "detail_scale_ratio", "density_fray", "lattice", "aniso", "isotropy", "density_imprint", "air_detail"]


def load(path):
    frames, summary = {}, None
    for line in open(path):
        if not line.strip():
            continue
        j = json.loads(line)
        if "frame" in j:
            frames[j["frame"]] = j
        elif j.get("command") == "measure":
            summary = j
    return frames, summary


def grid_bytes(path):
    """Bytes of each grid written alone (same half/Blosc settings), with Debian's pyopenvdb; {} without it."""
    code = ("import os, sys, pyopenvdb as v\n"
            "gs, m = v.readAll(sys.argv[1])\n"
            "for g in gs:\n"
            "    v.write('/tmp/.output_size_grid.vdb', grids=[g])\n"
            "    print(g.name, g.activeVoxelCount(), os.path.getsize('/tmp/.output_size_grid.vdb'))\n")
    try:
        out = subprocess.run(["/usr/bin/python3", "-c", code, path], capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return {}
    return {n: (int(a), int(b)) for n, a, b in (l.split() for l in out.splitlines())}


def main():
    noise, ref_dir, ref_measure = sys.argv[1:4]
    rf, rs = load(ref_measure)
    for i in range(4, len(sys.argv), 2):
        d, m = sys.argv[i], sys.argv[i + 1]
        files = sorted(f for f in os.listdir(d) if f.startswith("o.") and f.split(".")[1].isdigit())
        ratios = []
        for f in files:
            frame = int(f.split(".")[1])
            ratios.append((os.path.getsize(os.path.join(d, f)) / os.path.getsize(noise % frame), frame))
        ratios.sort()
        med, (worst, wf) = ratios[len(ratios) // 2][0], ratios[-1]
        print("%s: size / Blender noise: median %.2fx, worst %.2fx (frame %d), frames over 2x: %d, over 1.5x: %d"
              % (os.path.basename(d), med, worst, wf, sum(r > 2 for r, _ in ratios), sum(r > 1.5 for r, _ in ratios)))
        gb = grid_bytes(os.path.join(d, "o.%04d.vdb" % wf))
        nb = grid_bytes(noise % wf)
        if gb:
            print("  frame %d per grid (voxels, bytes): ours %s; Blender's noise %s" % (
                wf, ", ".join("%s %d %d" % (k, *v) for k, v in gb.items() if v[0]),
                ", ".join("%s %d %d" % (k, *v) for k, v in nb.items() if v[0])))
        if m == "-":
            continue
        vf, vs = load(m)
        if rs and vs:
            print("  medians against %s:" % os.path.basename(ref_dir), " ".join(
                "%s %+.2f%%" % (k, 100.0 * (vs[k]["median"] - rs[k]["median"]) / max(abs(rs[k]["median"]), 1e-12))
                for k in KEYS if isinstance(rs.get(k), dict) and isinstance(vs.get(k), dict)))
        moved = []
        for k in KEYS:
            worst = (0.0, None, None, None)
            for f in vf:
                x, y = vf[f].get(k), rf.get(f, {}).get(k)
                if x is None or y is None:
                    continue
                rel = abs(x - y) / max(abs(y), 1e-12)
                if rel > worst[0]:
                    worst = (rel, f, y, x)
            if worst[0] > 0.01:
                moved.append("%s %.1f%% at frame %d (%.4g -> %.4g)" % (k, 100 * worst[0], worst[1], worst[2], worst[3]))
        print("  single frames over 1%:", "; ".join(moved) if moved else "none")


main()
