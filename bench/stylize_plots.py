#!/usr/bin/python3
"""Figures and numbers of docs/stylize.md from the JSON lines bench/stylize_quality.sh wrote.

    /usr/bin/python3 bench/stylize_plots.py WORK OUTDIR

Debian's python3-matplotlib (under /usr/bin/python3). Prints the summary numbers the docs quote.
"""
import json
import os
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def load(path):
    rows = []
    if not os.path.exists(path):
        return rows
    with open(path) as f:
        for line in f:
            j = json.loads(line)
            if "frame" in j and "summary" not in j:
                rows.append(j)
    return rows


def trend(xs, ys):
    """Least-squares slope of ys over xs, per 100 frames."""
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    return 100.0 * sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx if sxx else 0.0


def summary(name, rows):
    if not rows:
        return
    # Ratios against the first frame with an interior (a young plume has none: its ratios are 0).
    f1 = next((r for r in rows if r["std_ratio"] > 0 and r["gradient_ratio"] > 0), None)
    if f1 is None:
        return
    every = rows  # IoU, edges and times over every frame; the ratios from the first frame with an interior
    rows = [r for r in rows if r["frame"] >= f1["frame"]]
    std = [r["std_ratio"] / f1["std_ratio"] for r in rows]
    grad = [r["gradient_ratio"] / f1["gradient_ratio"] for r in rows]
    frames = [r["frame"] for r in rows]
    cov = [r["coverage"] for r in rows]
    tc = [r["temporal_change"] for r in rows if "temporal_change" in r]
    iou = [r["iou"] for r in every]
    edge = [r["boundary_gradient_match"] for r in every]
    secs = sorted(r["seconds"] for r in every)
    print(f"{name}: {len(rows)} frames; coverage min {min(cov):.4f}; std/frame {f1['frame']} {min(std):.3f}..{max(std):.3f} "
          f"(last {std[-1]:.3f}, trend {trend(frames, std):+.3f}/100 fr); grad/frame {f1['frame']} {min(grad):.3f}..{max(grad):.3f} "
          f"(last {grad[-1]:.3f}, trend {trend(frames, grad):+.3f}/100 fr); std vs exemplar f{f1['frame']} {f1['std_ratio']:.3f} last "
          f"{rows[-1]['std_ratio']:.3f}; grad vs exemplar f{f1['frame']} {f1['gradient_ratio']:.3f} last {rows[-1]['gradient_ratio']:.3f}")
    if tc:
        mean = sum(tc) / len(tc)
        print(f"  temporal change mean {mean:.4f} max {max(tc):.4f} (max/mean {max(tc) / mean:.2f})")
    print(f"  IoU min {min(iou):.3f} mean {sum(iou) / len(iou):.3f}; boundary |grad a| histogram match min {min(edge):.3f} "
          f"mean {sum(edge) / len(edge):.3f}; median {secs[len(secs) // 2]:.2f} s/frame")
    adv = [(r["alpha_error_advected"], r["alpha_error_still"]) for r in rows if "alpha_error_advected" in r]
    if adv:
        better = sum(1 for a, s in adv if a < s)
        print(f"  alpha advection check: advected {sum(a for a, _ in adv) / len(adv):.5f} vs still "
              f"{sum(s for _, s in adv) / len(adv):.5f} (mean over {len(adv)} frame pairs; advected better in {better})")


def main():
    work, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)
    runs = {n: load(os.path.join(work, n + ".jsonl")) for n in
            ["uniform", "standard", "uniform-lambda0", "standard-lambda0", "plume", "plume-persp"]}
    for n, rows in runs.items():
        summary(n, rows)

    # Wash-out: std and gradient ratios (output / exemplar) and coverage over time.
    if runs["uniform"] and runs["standard"]:
        fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
        for n, style in [("uniform", "-"), ("standard", "--")]:
            rows = runs[n]
            fr = [r["frame"] for r in rows]
            ax[0].plot(fr, [r["std_ratio"] for r in rows], style, label=f"{n} NNF")
            ax[1].plot(fr, [r["gradient_ratio"] for r in rows], style, label=f"{n} NNF")
            ax[2].plot(fr, [100 * r["coverage"] for r in rows], style, label=f"{n} NNF")
        ax[0].set_title("interior luminance std, output / exemplar")
        ax[1].set_title("interior gradient energy, output / exemplar")
        ax[2].set_title("exemplar patches used (%)")
        for a in ax:
            a.set_xlabel("frame")
            a.grid(alpha=0.3)
            a.legend()
        fig.tight_layout()
        fig.savefig(os.path.join(out, "stylize-washout.png"), dpi=80)

    # Temporal change against the warped previous frame.
    if runs["uniform"] and runs["uniform-lambda0"]:
        fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
        for n, style in [("uniform", "-"), ("uniform-lambda0", "--"), ("standard", ":"), ("standard-lambda0", "-.")]:
            rows = [r for r in runs[n] if "temporal_change" in r]
            if rows:
                ax[0].plot([r["frame"] for r in rows], [r["temporal_change"] for r in rows], style, label=n)
        ax[0].set_title("mean |X^t - warped X^(t-1)| where lambda_q > 0")
        ax[0].set_xlabel("frame")
        ax[0].grid(alpha=0.3)
        ax[0].legend()
        for n, style in [("uniform", "-"), ("standard", "--")]:
            ax[1].plot([r["frame"] for r in runs[n]], [r["iou"] for r in runs[n]], style, label=n)
        ax[1].set_title("alpha IoU with the target mask")
        ax[1].set_xlabel("frame")
        ax[1].set_ylim(0.8, 1.0)
        ax[1].grid(alpha=0.3)
        ax[1].legend()
        fig.tight_layout()
        fig.savefig(os.path.join(out, "stylize-temporal.png"), dpi=80)

    # Boundary: |grad alpha| histograms, output vs exemplar (last frame of the uniform run).
    if runs["uniform"]:
        r = runs["uniform"][-1]
        fig, ax = plt.subplots(figsize=(6, 3.6))
        bins = [(i + 0.5) / 32 for i in range(16)]
        ax.bar([b - 0.007 for b in bins], r["boundary_gradient_histogram"], width=0.014, label="output (target boundary)")
        ax.bar([b + 0.007 for b in bins], r["exemplar_boundary_gradient_histogram"], width=0.014, label="exemplar boundary")
        ax.set_xlabel("|grad alpha| per pixel")
        ax.set_title(f"boundary alpha gradients, frame {r['frame']} (match {r['boundary_gradient_match']:.2f})")
        ax.legend()
        fig.tight_layout()
        fig.savefig(os.path.join(out, "stylize-boundary.png"), dpi=80)

    # Picture strip: frames across the run, uniform (top) and standard (bottom), over a dark background.
    if runs["uniform"] and runs["standard"]:
        n = len(runs["uniform"])
        picks = sorted({1, n // 4, n // 2, 3 * n // 4, n})
        cells = []
        for name in ["uniform", "standard"]:
            for f in picks:
                src = os.path.join(work, name, f"o.{f:04d}.png")
                dst = os.path.join(work, f"strip-{name}-{f:04d}.png")
                subprocess.run(["oiiotool", src, "--pattern", "constant:color=0.07,0.075,0.09,1", "256x256", "4", "--over",
                                "--ch", "R,G,B", "-o", dst], check=True)
                cells.append(dst)
        subprocess.run(["oiiotool"] + cells + ["--mosaic:pad=4", f"{len(picks)}x2", "-o",
                                               os.path.join(out, "stylize-washout-strip.png")], check=True)
        print("strip frames:", picks)


if __name__ == "__main__":
    main()
