"""Blender's own up-res of the shared blender-steady-64 scene (../shared/data/blender_plume_steady.py), run as that
script runs it with Mantaflow's "Noise" (wavelet turbulence) switched on at factor NOISE: the anchor of issue 42's
steady pair, whose target is blender-steady-64 down-sampled by 4.

    blender -b --factory-startup --python steady_noise.py -- RES OUTDIR FRAMES [NOISE]

RES 16 and NOISE 4 give a 16^3 base and a 64^3 noise density (OUTDIR/noise/fluid_noise_####.vdb) beside the shared
64^3 simulation. The scene is the shared script's text, unchanged but for the noise lines added after its vorticity
setting, so the two cannot drift apart. Note that Blender's 16^3 base simulation is not the down-sampled 64^3 one
that the transfer takes as its target: the noise is of the same scene at the same resolution, not of the same grid.
"""
import os
import sys

argv = sys.argv[sys.argv.index("--") + 1:]
noise = int(argv[3]) if len(argv) > 3 else 4
here = os.path.dirname(os.path.abspath(__file__))
scene = os.environ.get("VDBTURB_SHARED_DATA", os.path.join(here, "..", "..", "..", "shared", "data"))
path = os.path.join(scene, "blender_plume_steady.py")
text = open(path).read()
anchor = "ds.vorticity = 0.2"
if anchor not in text:
    sys.exit("steady_noise.py: %s no longer sets '%s'; update the anchor" % (path, anchor))
text = text.replace(anchor, anchor + "\nds.use_noise = True; ds.noise_scale = %d" % noise, 1)
exec(compile(text, path, "exec"))
