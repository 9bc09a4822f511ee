"""Blender's own up-res of the shared blender-plume2-32 scene (../shared/data/blender_plume_cube.py): the
4x4x4 cube domain at 32^3 with a sphere inflow of radius 0.5 on the floor, baked with Mantaflow's "Noise"
(wavelet turbulence) at factor NOISE, so that its noise files sit beside the shared blender-plume2-128 source.

    blender -b --factory-startup --python cube_noise.py -- OUTDIR [FRAMES] [NOISE] [RES] [THREADS]

Defaults: 30 frames, NOISE 4, RES 32. Writes OUTDIR/data/fluid_data_####.vdb (the base sim: the transfer's
target) and OUTDIR/noise/fluid_noise_####.vdb (Blender's up-res density), with bake_replay's JSON lines.
The scene is the shared script's (a 4x4x4 cube domain at 24 fps), not mantaflow_scene's 4x4x6 domain.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mantaflow_scene as ms  # noqa: E402

a = ms.script_args(["OUTDIR", "FRAMES", "NOISE", "RES", "THREADS"],
                   {"FRAMES": "30", "NOISE": "4", "RES": "32", "THREADS": "0"})
res, frames, noise = int(a["RES"]), int(a["FRAMES"]), int(a["NOISE"])
ms.new_scene(frames)
dom, ds = ms.add_domain(res, a["OUTDIR"], frames, size=(4.0, 4.0, 4.0))
ds.use_noise = True
ds.noise_scale = noise
ms.add_sphere_inflow(0.5, (0, 0, -1.5))
ms.bake_replay(dom, frames, "blender cube plume res %d noise x%d" % (res, noise), int(a["THREADS"]))
