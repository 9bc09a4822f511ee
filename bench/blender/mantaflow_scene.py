"""Shared pieces of the Blender 3.4 Mantaflow scene scripts in this folder (imported by them, not run).

All scenes share one world domain: a 4 x 4 x 6 box centred on the origin (floor at z = -3), so that a
cache baked with resolution_max = 24 (16x16x24 cells, voxel 0.25) and one baked with resolution_max = 192
(128x128x192 cells, voxel 0.03125) cover the same space: the 3D configuration of Sato et al.

Blender writes the caches as OpenVDB files OUTDIR/data/fluid_data_####.vdb (and, with the noise up-res,
OUTDIR/noise/fluid_noise_####.vdb). Velocity is stored on a MAC grid in grid cells per time step
(see ../shared/data/README.md).
"""
import json
import os
import resource
import sys
import time

import bpy

T_IMPORT = time.time()  # the scripts import this module first: totals count scene set-up, not Blender's start-up
DOMAIN_SIZE = (4.0, 4.0, 6.0)  # world units; the longest side is z, so resolution_max counts cells along z


def script_args(names, defaults):
    """The arguments after '--' on Blender's command line, as a dict; names without a default are required."""
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    if len(argv) < sum(1 for n in names if n not in defaults) or len(argv) > len(names):
        sys.stderr.write("usage: blender -b --factory-startup --python SCRIPT -- %s\n"
                         % " ".join(n if n not in defaults else "[%s]" % n for n in names))
        sys.exit(2)
    out = dict(defaults)
    out.update(zip(names, argv))
    return out


def new_scene(frames):
    """An empty scene at 24 fps whose frame range is 1..frames."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, frames
    sc.render.fps = 24
    return sc


def add_domain(res_max, cache_dir, frames, cache_type="REPLAY", size=DOMAIN_SIZE):
    """A gas domain filling `size` (DOMAIN_SIZE), cells along its longest side = res_max, OpenVDB cache in cache_dir."""
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 0.0))
    dom = bpy.context.active_object
    dom.name = "Domain"
    dom.scale = size
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    bpy.ops.object.modifier_add(type="FLUID")
    m = dom.modifiers["Fluid"]
    m.fluid_type = "DOMAIN"
    ds = m.domain_settings
    ds.domain_type = "GAS"
    ds.resolution_max = res_max
    ds.cache_directory = os.path.abspath(cache_dir)
    ds.cache_type = cache_type
    ds.cache_data_format = "OPENVDB"
    ds.cache_noise_format = "OPENVDB"
    ds.cache_frame_start, ds.cache_frame_end = 1, frames
    return dom, ds


def add_sphere_inflow(radius, location, velocity=None):
    """A smoke inflow sphere; velocity (world units per second) makes it a jet."""
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=location)
    e = bpy.context.active_object
    bpy.ops.object.modifier_add(type="FLUID")
    e.modifiers["Fluid"].fluid_type = "FLOW"
    fs = e.modifiers["Fluid"].flow_settings
    fs.flow_type = "SMOKE"
    fs.flow_behavior = "INFLOW"
    if velocity is not None:
        fs.use_initial_velocity = True
        fs.velocity_coord = velocity
    return e


def machine():
    model = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return "%s (%d threads)" % (model, os.cpu_count() or 0)


def bake_replay(dom, frames, label, threads=0):
    """Steps the REPLAY cache through frames 1..frames (each frame_set simulates and writes that frame).

    Prints, on stdout, one JSON line per frame ({"frame", "seconds"}) and a summary line in the form
    vdbturb's --json summary uses, so bench/run.sh reads Blender runs like its own. The total includes
    scene set-up after Blender's start-up; peak RSS is the Blender process's own.
    """
    bpy.context.view_layer.objects.active = dom
    sc = bpy.context.scene
    seconds = []
    for f in range(1, frames + 1):
        t = time.time()
        sc.frame_set(f)
        seconds.append(time.time() - t)
        print(json.dumps({"frame": f, "seconds": round(seconds[-1], 4)}, separators=(",", ":")), flush=True)
    total = time.time() - T_IMPORT
    s = sorted(seconds)
    n = len(s)
    median = s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])
    summary = {"summary": True, "command": label, "frames": n, "failed": 0, "median_s_per_frame": median,
               "total_s": total, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
               "threads": threads if threads > 0 else (os.cpu_count() or 0), "machine": machine(),
               "blender": bpy.app.version_string}
    print(json.dumps(summary, separators=(",", ":")), flush=True)  # compact, as vdbturb prints it
    return summary


PLUME_RADIUS = 0.5  # the emitter sphere rests on the floor
PLUME_SPEED = 2.0  # inflow speed up, world units per second (buoyancy alone lifts it 1.5 units in 30 frames)


def plume_scene(res_z, out, frames, noise=0, speed=PLUME_SPEED, radius=PLUME_RADIUS):
    """The buoyant plume: sphere inflow of `radius` (0.5) on the floor blowing up at speed, default buoyancy.

    noise > 0 turns on Blender's "Noise" up-res (wavelet turbulence on the density) at that factor. A larger
    radius and speed make the heavy target of bench/heavy_pairs.sh, whose smoke fills much of the box.
    """
    new_scene(frames)
    dom, ds = add_domain(res_z, out, frames)
    if noise > 0:
        ds.use_noise = True
        ds.noise_scale = noise
    add_sphere_inflow(radius, (0.0, 0.0, -DOMAIN_SIZE[2] / 2 + radius), (0.0, 0.0, speed))
    return dom
