"""The table of bench/look.sh: issue 42's numbers of vdbturb's transfer beside Blender's noise up-res and Blender's
high-res simulation of the same scene, with the goals checked.

    python3 bench/look_table.py PAIR PREFIX

reads PREFIX.vdbturb.json, PREFIX.noise.json and PREFIX.hires.json (`vdbturb measure` JSON lines) and prints a
Markdown table: per number the range and the median over frames of each (from the goal's first frame), the goal and
whether vdbturb meets it.
"Frame k" below counts the measured frames from 1 (the steady pair starts at cache frame 91).
"""
import json
import statistics
import sys


def load(path):
    rows = {}
    try:
        for line in open(path):
            if line.startswith("{"):
                r = json.loads(line)
                if "frame" in r:
                    rows[r["frame"]] = r
    except FileNotFoundError:
        pass
    return [rows[k] for k in sorted(rows)]


def series(rows, key, first=1):
    return [r.get(key) for r in rows[first - 1:] if r.get(key) is not None]


def cell(v, worst):
    if not v:
        return "-"
    return "%.3g-%.3g (%.3g)" % (min(v), max(v), statistics.median(v))


pair, prefix = sys.argv[1], sys.argv[2]
ours, noise, hires = (load(prefix + "." + n + ".json") for n in ("vdbturb", "noise", "hires"))
if not ours:
    sys.exit("look_table: no frames in %s.vdbturb.json" % prefix)

# name, goal text, which end is worst, check(ours series from the goal's first frame) -> bool, first frame
def within(lo, hi):
    return lambda v: all(lo <= x <= hi for x in v)


def below(b):
    return lambda v: all(x <= b for x in v)


def med(v):
    return statistics.median(v) if v else None


def against(key, first, test):
    """A goal stated against an anchor's median of the same number."""
    def check(v, anchor):
        a = med(series(anchor, key, first))
        return a is not None and bool(v) and test(med(v), a)
    return check


src_div = med(series(ours, "div_rel_source"))
src_tcoh = med(series(ours, "tcoh_source"))
rows = [
    ("lattice", "<= 0.1 every frame", max, below(0.1), 1),
    ("vort_peak_ratio", "<= 1.25 every frame", max, below(1.25), 1),
    ("detail_scale_ratio", "0.8-1.25 from frame 3", max, within(0.8, 1.25), 3),
    ("aniso_ratio", "0.8-1.25 from frame 3", max, within(0.8, 1.25), 3),
    ("detail_profile_ratio", "<= 1.5 every frame (no emitter band)", max, below(1.5), 1),
    ("density_fray", "median 5-30 <= noise's; <= 1.15x high-res's", max, None, 5),
    ("edge_crispness", "median >= noise's; 0.8-1.25 of high-res's", min, None, 5),
    ("lf_err", "<= 0.05", max, below(0.05), 1),
    ("hf_ratio", "0.8-1.25 (from frame 3)", max, within(0.8, 1.25), 3),
    ("div_rel", "<= the source's (median %.3g)" % (src_div or 0), max,
     (lambda v: src_div is not None and med(v) <= src_div), 1),
    ("block", "<= 1.05", max, below(1.05), 1),
    ("tcoh", "<= the source's (median %.3g)" % (src_tcoh or 0), max,
     (lambda v: src_tcoh is not None and med(v) <= src_tcoh), 1),
    ("mass_ratio", "0.9-1.1", max, within(0.9, 1.1), 1),
    ("peak_ratio", "<= 1.05", max, below(1.05), 1),
]
print("\n### %s: %d frames (min-max (median) over frames)\n" % (pair, len(ours)))
print("| number | vdbturb | Blender noise | Blender high-res | goal | met |")
print("|---|---|---|---|---|---|")
for key, goal, worst, check, first in rows:
    v = series(ours, key, first)
    if key == "density_fray":
        n, h = med(series(noise, key, first)), med(series(hires, key, first))
        nf = {r["frame"]: r.get(key) for r in noise}
        frames_over = [r["frame"] for r in ours[first - 1:] if r.get(key) is not None and nf.get(r["frame"])
                       and r[key] > 1.2 * nf[r["frame"]]]
        ok = bool(v) and n is not None and h is not None and med(v) <= n and med(v) <= 1.15 * h and not frames_over
    elif key == "edge_crispness":
        n, h = med(series(noise, key, first)), med(series(hires, key, first))
        ok = bool(v) and n is not None and h is not None and med(v) >= n and 0.8 <= med(v) / h <= 1.25
    else:
        ok = bool(v) and check(v)
    print("| `%s` | %s | %s | %s | %s | %s |" % (key, cell(v, worst), cell(series(noise, key, first), worst),
                                               cell(series(hires, key, first), worst), goal, "yes" if ok else "**no**"))
