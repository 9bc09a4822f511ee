"""Blender's own up-res of the paper's 3D target: the plume of plume.py at 16x16x24 with Mantaflow's
"Noise" (wavelet turbulence) at factor 8, giving a 128x128x192 density, baked and timed end to end
(the base simulation included, as a Blender user would run it).

    blender -b --factory-startup --python plume_noise.py -- OUTDIR [FRAMES] [NOISE] [RES_Z] [THREADS] [RADIUS] [SPEED]

Defaults: 30 frames, NOISE 8, RES_Z 24, the emitter's RADIUS 0.5 and SPEED 2 (bench/heavy_pairs.sh: larger). Writes OUTDIR/data/fluid_data_####.vdb (the base sim) and
OUTDIR/noise/fluid_noise_####.vdb (the up-res density; Blender's noise writes no high-res velocity).
One JSON line per frame and a vdbturb-style summary line on stdout (bench/run.sh blender-noise).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mantaflow_scene as ms  # noqa: E402

a = ms.script_args(["OUTDIR", "FRAMES", "NOISE", "RES_Z", "THREADS", "RADIUS", "SPEED"],
                   {"FRAMES": "30", "NOISE": "8", "RES_Z": "24", "THREADS": "0", "RADIUS": str(ms.PLUME_RADIUS),
                    "SPEED": str(ms.PLUME_SPEED)})
res, frames, noise = int(a["RES_Z"]), int(a["FRAMES"]), int(a["NOISE"])
dom = ms.plume_scene(res, a["OUTDIR"], frames, noise, float(a["SPEED"]), float(a["RADIUS"]))
ms.bake_replay(dom, frames, "blender plume res_z %d noise x%d" % (res, noise), int(a["THREADS"]))
