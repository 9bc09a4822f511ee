"""Two-jet swirl, the high-res source of the paper's 3D configuration (Sato et al.: 128x128x192).

    blender -b --factory-startup --python two_jet_swirl.py -- RES_Z OUTDIR [FRAMES] [SPEED] [THREADS] [RADIUS]

RES_Z: cells along z (192 gives 128x128x192 cells of 0.03125 in the 4x4x6 domain). Two smoke jets near
the floor blow towards each other along +x and -x, offset in y by +-OFFSET, so they pass each other and
their momenta form a couple about z: the smoke swirls, the shear layers between the jets roll up into
turbulence, and buoyancy carries it up. SPEED: jet speed in world units per second (default 8). RADIUS: the
jets' inflow spheres (0.4; bench/heavy_pairs.sh's heavy source: larger, so the smoke fills most of the box).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mantaflow_scene as ms  # noqa: E402

a = ms.script_args(["RES_Z", "OUTDIR", "FRAMES", "SPEED", "THREADS", "RADIUS"],
                   {"FRAMES": "30", "SPEED": "8", "THREADS": "0", "RADIUS": "0.4"})
res, out, frames, speed = int(a["RES_Z"]), a["OUTDIR"], int(a["FRAMES"]), float(a["SPEED"])
RADIUS, X, OFFSET, Z = float(a["RADIUS"]), 1.4, 0.6, -ms.DOMAIN_SIZE[2] / 2 + 1.0
ms.new_scene(frames)
dom, ds = ms.add_domain(res, out, frames)
ms.add_sphere_inflow(RADIUS, (-X, -OFFSET, Z), (speed, 0.0, 0.0))
ms.add_sphere_inflow(RADIUS, (X, OFFSET, Z), (-speed, 0.0, 0.0))
ms.bake_replay(dom, frames, "blender two-jet swirl res_z %d speed %g" % (res, speed), int(a["THREADS"]))
