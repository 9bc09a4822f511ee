#!/usr/bin/python3
"""How fast the texture of a rendered cache moves, against the cache's own projected velocity (docs/animate.md,
"The shared steady plume"). Run by bench/animate_quality.sh steady64; needs numpy (Debian python3-numpy).

    animate_pattern_speed.py DIR KYMOGRAPH.ppm

DIR holds f.NNNN.tif (the example's renders) and v.tif (the cache's projected velocity, pixels per frame, as
`vdbturb animate --dump` writes it), all float TIFFs without compression (oiiotool -d float --compression none).
Prints, per band of 24 rows of the column's core (where |v| at mid-height is over half its maximum), the vertical
shift per frame that best correlates consecutive differences D_i = F_i - mean(F) with each other, beside the
cache's mean upward speed there; writes a kymograph of D along the core (rows: image rows, columns: frames) with the
paths the cache's velocity would carry texture along drawn in red.
"""
import glob
import struct
import sys

import numpy as np


def read_tif(path):
    data = open(path, "rb").read()
    bo = "<" if data[:2] == b"II" else ">"
    off = struct.unpack(bo + "I", data[4:8])[0]
    n = struct.unpack(bo + "H", data[off:off + 2])[0]
    tags = {}
    for k in range(n):
        e = data[off + 2 + 12 * k:off + 14 + 12 * k]
        tag, typ, cnt = struct.unpack(bo + "HHI", e[:8])
        size, fmt = {3: (2, "H"), 4: (4, "I")}.get(typ, (4, "I"))
        raw = e[8:8 + size * cnt] if size * cnt <= 4 else data[struct.unpack(bo + "I", e[8:12])[0]:][:size * cnt]
        tags[tag] = struct.unpack(bo + fmt * cnt, raw)
    if tags.get(259, (1,))[0] != 1:
        sys.exit(path + ": compressed TIFF (write it with --compression none)")
    w, h, spp = tags[256][0], tags[257][0], tags.get(277, (1,))[0]
    buf = b"".join(data[o:o + c] for o, c in zip(tags[273], tags[279]))
    return np.frombuffer(buf, dtype=bo + "f4").reshape(h, w, spp).astype(np.float64)


def luminance(a):
    return 0.2126 * a[..., 0] + 0.7152 * a[..., 1] + 0.0722 * a[..., 2]


def sample_rows(img, rows, x0, x1):
    """img at fractional rows (bilinear along y), columns x0..x1-1."""
    h = img.shape[0]
    r = np.clip(rows, 0, h - 1)
    r0 = np.floor(r).astype(int)
    r1 = np.minimum(r0 + 1, h - 1)
    f = (r - r0)[:, None]
    return img[r0, x0:x1] * (1 - f) + img[r1, x0:x1] * f


def main():
    d, out = sys.argv[1], sys.argv[2]
    frames = [luminance(read_tif(f)) for f in sorted(glob.glob(d + "/f.*.tif"))]
    v = read_tif(d + "/v.tif")
    A = np.mean(frames, axis=0)
    D = [f - A for f in frames]
    h, w = A.shape
    speed = np.hypot(v[..., 0], v[..., 1])
    cols = np.where(speed[h // 2] > 0.5 * speed[h // 2].max())[0]
    x0, x1 = int(cols.min()), int(cols.max()) + 1
    print("core columns %d-%d, %d frames" % (x0, x1 - 1, len(frames)))
    for y0 in range(24, h - 40, 24):
        rows = np.arange(y0, y0 + 24, dtype=float)
        best = (0.0, -2.0)
        for shift in np.arange(0.0, 9.0, 0.2):
            c = n1 = n2 = 0.0
            for i in range(len(D) - 1):
                src = sample_rows(D[i], rows + shift, x0, x1)  # the texture moves up: row y came from y + shift
                dst = D[i + 1][y0:y0 + 24, x0:x1]
                c += np.sum(src * dst)
                n1 += np.sum(src * src)
                n2 += np.sum(dst * dst)
            r = c / np.sqrt(n1 * n2)
            if r > best[1]:
                best = (shift, r)
        up = -v[y0:y0 + 24, x0:x1, 1].mean()
        print("rows %3d-%3d: texture %.1f px/frame (correlation %.2f), cache velocity %.2f px/frame, ratio %.2f"
              % (y0, y0 + 23, best[0], best[1], up, best[0] / up))
    # Kymograph: the core's mean D per row, frame after frame (4 columns each), and the cache's paths in red.
    xc0, xc1 = (x0 + x1) // 2 - 5, (x0 + x1) // 2 + 5
    K = np.stack([dd[:, xc0:xc1].mean(axis=1) for dd in D], axis=1)
    K = np.clip(K / (3 * K.std()) * 0.5 + 0.5, 0, 1)
    img = np.repeat(np.stack([K, K, K], axis=2), 4, axis=1)
    up = -v[:, xc0:xc1, 1].mean(axis=1)
    T = len(D)
    for start in range(0, T, 10):
        y, t = h - 36.0, start
        while y > 5 and t < T:
            img[int(y), 4 * t:4 * t + 4] = [1.0, 0.2, 0.2]
            y -= up[int(y)]
            t += 1
    with open(out, "wb") as f:
        f.write(b"P6\n%d %d\n255\n" % (img.shape[1], img.shape[0]))
        f.write((img * 255).astype(np.uint8).tobytes())


if __name__ == "__main__":
    main()
