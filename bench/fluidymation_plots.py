#!/usr/bin/python3
"""Tables and figures of the Fluidymation section of docs/stylize.md, from bench/fluidymation_quality.sh.

    /usr/bin/python3 bench/fluidymation_plots.py WORK OUTDIR

Debian's python3-matplotlib and numpy (under /usr/bin/python3); oiiotool for the preview sheets.
Prints the markdown tables the docs quote.
"""
import json
import os
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

PAPER = np.array([0.96, 0.95, 0.92])
VARIANTS = [("default", "Table 1"), ("dir0", "w_dir = 0"), ("ext0", "w_ext = 0"), ("temp0", "w_temp = 0"),
            ("uni0", "w_uni = 0"), ("bound0", "w_bound = 0")]


def load(path):
    rows = []
    if os.path.exists(path):
        with open(path) as f:
            for line in f:
                j = json.loads(line)
                if "frame" in j and "summary" not in j and j.get("masked_pixels", 0) > 0:
                    rows.append(j)
    return rows


def weighted(rows, key, weight, first=2):
    num = den = 0.0
    for r in rows:
        if r["frame"] < first or key not in r or r[key] < 0:
            continue
        w = r[weight] if weight else 1.0
        num += w * r[key]
        den += w
    return num / den if den else float("nan")


def summary(name, rows):
    if not rows:
        return None
    secs = sorted(r["seconds"] for r in rows if "seconds" in r)
    return {
        "run": name,
        "sin": weighted(rows, "mean_abs_sin", "moving_pixels"),
        "speed": weighted(rows, "speed_correlation", None),
        "extent": weighted(rows, "extent_correlation", None),
        "still": weighted(rows, "stationary_change", "stationary_pixels"),
        "coverage": weighted(rows, "coverage", None, 1),
        "distinct": weighted(rows, "distinct_patches", None, 1),
        "contrast": weighted(rows, "contrast_ratio", None, 1),
        "energy": sum(r["energy"]["total"] for r in rows) / len(rows),
        "s": secs[len(secs) // 2] if secs else float("nan"),
        "px": sum(r["masked_pixels"] for r in rows) / len(rows),
    }


def table(work, names):
    print("| run | mean abs sin (moving) | speed corr | extent corr | still change | coverage | distinct | contrast | mean E | s/frame |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    out = {}
    for n in names:
        s = summary(n, load(os.path.join(work, n + ".jsonl")))
        if not s:
            continue
        out[n] = s
        print("| %s | %.3f | %.2f | %.2f | %.4f | %.1f%% | %.2f | %.2f | %.1f | %.2f |" % (
            n, s["sin"], s["speed"], s["extent"], s["still"], 100 * s["coverage"], s["distinct"], s["contrast"], s["energy"], s["s"]))
    return out


def over_paper(path):
    img = mpimg.imread(path)
    if img.shape[2] == 4:
        a = img[:, :, 3:4]
        return img[:, :, :3] * a + PAPER * (1 - a)
    return img[:, :, :3]


def ablation_grid(work, target, frames, out):
    rows = [(v, label) for v, label in VARIANTS if os.path.exists(os.path.join(work, "%s-%s" % (target, v)))]
    if not rows:
        return
    fig, axes = plt.subplots(len(rows), len(frames), figsize=(2.4 * len(frames), 2.4 * len(rows) * (0.5 if target == "stroke" else 1.0) + 0.3))
    for i, (v, label) in enumerate(rows):
        for k, f in enumerate(frames):
            ax = axes[i][k]
            ax.imshow(over_paper(os.path.join(work, "%s-%s" % (target, v), "o.%04d.png" % f)))
            ax.set_xticks([])
            ax.set_yticks([])
            if k == 0:
                ax.set_ylabel(label, fontsize=9)
            if i == 0:
                ax.set_title("frame %d" % f, fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def metric_curves(work, out):
    panels = [("mean_abs_sin", "dir0", "mean |sin| (moving pixels)"), ("speed_correlation", "ext0", "speed correlation"),
              ("stationary_change", "temp0", "mean |T^j - T^(j-1)| (still pixels)"), ("coverage", "uni0", "exemplar coverage")]
    fig, axes = plt.subplots(2, 4, figsize=(15, 6.5))
    for row, target in enumerate(["grow", "stroke"]):
        for col, (key, abl, title) in enumerate(panels):
            ax = axes[row][col]
            for name, style in (("default", "-"), (abl, "--")):
                rows = load(os.path.join(work, "%s-%s.jsonl" % (target, name)))
                xs = [r["frame"] for r in rows if key in r and r[key] >= 0]
                ys = [r[key] for r in rows if key in r and r[key] >= 0]
                ax.plot(xs, ys, style, label="Table 1" if name == "default" else "w_%s = 0" % abl[:-1])
            if key == "mean_abs_sin":
                ax.axhline(2 / np.pi, color="grey", lw=0.8, ls=":", label="random (0.64)")
            ax.set_title("%s: %s" % (target, title), fontsize=9)
            ax.set_xlabel("frame", fontsize=8)
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)


def exemplar_strip(work, out):
    ink = os.path.join(work, "ink")
    if not os.path.isdir(ink):
        return
    frames = [1, 6, 12, 18, 24, 30]
    fig, axes = plt.subplots(1, len(frames), figsize=(2.6 * len(frames), 2.3))
    for ax, f in zip(axes, frames):
        ax.imshow(over_paper(os.path.join(ink, "ink.%04d.png" % f)))
        m = mpimg.imread(os.path.join(ink, "ink_mask.%04d.png" % f))
        ax.contour(m[:, :, 0] if m.ndim == 3 else m, levels=[0.5], colors="orange", linewidths=0.6)
        ax.set_title("frame %d" % f, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)


def sheets(work, name, frames, out, width=1400):
    paths = [os.path.join(work, name, "preview", "fluidymation.%04d.png" % f) for f in frames]
    paths = [p for p in paths if os.path.exists(p)]
    if paths:
        subprocess.run(["oiiotool"] + paths + ["--mosaic", "1x%d" % len(paths), "--resize", "%dx0" % width, "-o", out], check=True)


def main():
    work, outdir = sys.argv[1], sys.argv[2]
    os.makedirs(outdir, exist_ok=True)
    for target in ("grow", "stroke"):
        print("\n%s" % target)
        table(work, ["%s-%s" % (target, v) for v, _ in VARIANTS])
        ablation_grid(work, target, [5, 15, 25, 30], os.path.join(outdir, "fluidy-ablation-%s.png" % target))
    print("\nplume")
    table(work, ["plume-default", "plume-b10", "plume-b10-temp0", "plume-b10-side"])
    metric_curves(work, os.path.join(outdir, "fluidy-metrics.png"))
    exemplar_strip(work, os.path.join(outdir, "fluidy-exemplar.png"))
    sheets(work, "plume-b10", [10, 20, 30], os.path.join(outdir, "fluidy-plume-sheet.png"))
    sheets(work, "plume-b10-side", [30], os.path.join(outdir, "fluidy-plume-side.png"))
    sheets(work, "stroke-default", [20], os.path.join(outdir, "fluidy-stroke-preview.png"))


if __name__ == "__main__":
    main()
