"""Buoyant smoke plume, the low-res target of the paper's 3D configuration (Sato et al.: 16x16x24).

    blender -b --factory-startup --python plume.py -- RES_Z OUTDIR [FRAMES] [THREADS]

RES_Z: cells along z (24 gives 16x16x24 cells of 0.25 in the 4x4x6 domain). THREADS only labels the
summary line; pass Blender's own -t N to limit its threads.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mantaflow_scene as ms  # noqa: E402

a = ms.script_args(["RES_Z", "OUTDIR", "FRAMES", "THREADS"], {"FRAMES": "30", "THREADS": "0"})
res, frames = int(a["RES_Z"]), int(a["FRAMES"])
dom = ms.plume_scene(res, a["OUTDIR"], frames)
ms.bake_replay(dom, frames, "blender plume res_z %d" % res, int(a["THREADS"]))
