"""The Blender add-on in real Blender, headless (docs/blender_addon.md); ctest runs it as `blender_addon`.

    BLENDER_USER_SCRIPTS=DIR/scripts BLENDER_USER_CONFIG=DIR/config \
    blender -b --factory-startup --python-exit-code 1 --python tests/blender/test_addon.py -- \
        --zip build/vdbturb_addon.zip --vdbturb build/tools/vdbturb --data ../shared/data --work DIR

Bakes a small smoke domain that is moved, turned and scaled, with its emitter off the domain's centre, installs
the add-on from its zip and runs it with the shared 128^3 plume as the source. Checks the imported Volume (grids,
frames, placement against the emitter), a Cycles render, a factor that needs a source proxy, Cancel, Resume and
a bad executable. The user paths must lie under DIR: the add-on is installed there, not in ~/.config.
"""
import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time
import traceback

import bpy
from mathutils import Euler, Matrix, Vector

DOMAIN_AT, DOMAIN_TURN, DOMAIN_SCALE = Vector((1, 2, 3)), math.radians(30), Vector((1.5, 1.0, 2.0))
EMITTER_LOCAL, EMITTER_RADIUS = Vector((0.4, -0.3, -0.7)), 0.3  # in the domain's object space (a 2-unit cube)
CELL = 0.125  # world cell: the largest world extent 4 over resolution 32; the source's 0.03125 makes factor 4
BAKED = 10


def check(ok, message):
    if not ok:
        raise AssertionError(message)


def arguments():
    parser = argparse.ArgumentParser()
    for name in ("zip", "vdbturb", "data", "work"):
        parser.add_argument("--" + name, required=True)
    args = parser.parse_args(sys.argv[sys.argv.index("--") + 1:])
    args.work, args.data = os.path.abspath(args.work), os.path.abspath(args.data)
    return args


def install(zip_path, work):
    scripts = bpy.utils.user_resource('SCRIPTS')
    check(os.path.abspath(scripts).startswith(work),
          f"user scripts {scripts} lie outside {work}: set BLENDER_USER_SCRIPTS (see this file's docstring)")
    shutil.rmtree(os.path.join(scripts, "addons", "vdbturb_addon"), ignore_errors=True)
    bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True)
    bpy.ops.preferences.addon_enable(module="vdbturb_addon")
    import vdbturb_addon
    check(vdbturb_addon.__file__.startswith(scripts), f"add-on loaded from {vdbturb_addon.__file__}, not the zip")
    return vdbturb_addon


def bake_domain(cache):
    """A 2-unit cube moved, turned about z and scaled (3x2x4 world units, 24x16x32 cells), baked to OpenVDB."""
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, BAKED
    bpy.ops.mesh.primitive_cube_add(size=2, location=DOMAIN_AT, rotation=(0, 0, DOMAIN_TURN))
    domain = bpy.context.active_object
    domain.name, domain.scale = "Smoke Domain", DOMAIN_SCALE
    bpy.ops.object.modifier_add(type='FLUID')
    mod = domain.modifiers["Fluid"]
    mod.fluid_type = 'DOMAIN'
    ds = mod.domain_settings
    ds.domain_type, ds.resolution_max = 'GAS', 32
    ds.cache_directory, ds.cache_type, ds.cache_data_format = cache, 'REPLAY', 'OPENVDB'
    ds.cache_frame_start, ds.cache_frame_end = 1, BAKED
    # Not domain.matrix_world: evaluating the domain before its emitter exists would start its cache empty.
    emitter_at = Matrix.LocRotScale(DOMAIN_AT, Euler((0, 0, DOMAIN_TURN)), DOMAIN_SCALE) @ EMITTER_LOCAL
    bpy.ops.mesh.primitive_uv_sphere_add(radius=EMITTER_RADIUS, location=emitter_at)
    emitter = bpy.context.active_object
    bpy.ops.object.modifier_add(type='FLUID')
    emitter.modifiers["Fluid"].fluid_type = 'FLOW'
    flow = emitter.modifiers["Fluid"].flow_settings
    flow.flow_type, flow.flow_behavior = 'SMOKE', 'INFLOW'
    emitter.hide_render = True
    # A Replay cache is baked by playing it; going back to its first frame would free it (frames 2+ are read).
    for frame in range(1, BAKED + 1):
        scene.frame_set(frame)
    bpy.context.view_layer.objects.active = domain
    domain.select_set(True)
    return domain, emitter_at


def vdb_info(exe, path):
    run = subprocess.run([exe, "info", "--json", path], capture_output=True, text=True)
    check(run.returncode == 0, f"vdbturb info {path}: exit {run.returncode}: {run.stderr[-500:]}")
    return json.loads(run.stdout)["files"][0]


def density_box(exe, path, matrix):
    """The density grid's world bounds in the file, taken through matrix: the box's (min, max) corners."""
    grid = next(g for g in vdb_info(exe, path)["grids"] if g["name"] == "density")
    lo, hi = grid["world_bounds"]
    corners = [matrix @ Vector((x, y, z)) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    return (Vector([min(c[i] for c in corners) for i in range(3)]),
            Vector([max(c[i] for c in corners) for i in range(3)]))


def leftovers(folder):
    """vdbturb's temporary files (".NAME.tmpPID_N") left in a folder."""
    return [n for n in os.listdir(folder) if n.startswith(".") and ".tmp" in n]


def run_blocking(addon):
    started = time.monotonic()
    result = bpy.ops.vdbturb.run(wait=True)
    run = addon.ui.current_run()
    check(result == {'FINISHED'} and run.job.state == "done",
          f"run: {result}, job {run.job.state}: {run.job.error}")
    return run, time.monotonic() - started


def check_run_and_import(addon, args, domain, emitter_at):
    settings = domain.vdbturb
    settings.source = os.path.join(args.data, "blender-plume2-128")  # a folder: the add-on finds its pattern
    settings.frames, settings.threads = "3-8", 2
    check(bpy.ops.vdbturb.check() == {'FINISHED'}, "check")
    plan = [line for line in settings.plan.split("\n") if not line.startswith("warning")]
    check(plan[0] == "ratio 4" and [p.split(":")[0] for p in plan[1:]] == ["output lattice", "output size",
                                                                             "memory", "time"], f"plan {plan}")
    check("starts fresh at frame 3" in settings.plan, "the plan's warnings")
    settings.preroll = 2  # frames 1-2 run first, unwritten: the warning goes
    bpy.ops.vdbturb.check()
    check("ratio 4" in settings.plan and "starts fresh" not in settings.plan, f"plan with preroll: {settings.plan}")
    run, seconds = run_blocking(addon)
    settings.preroll = 0
    job = run.job
    out = os.path.join(domain.modifiers["Fluid"].domain_settings.cache_directory, "vdbturb")
    check(job.steps[-1].argv[job.steps[-1].argv.index("--source") + 1]
          == os.path.join(args.data, "blender-plume2-128", "fluid_data_####.vdb"), "the source folder's pattern")
    check([f["frame"] for f in job.frames] == list(range(3, 9)), f"frames written: {[f['frame'] for f in job.frames]}")
    percents = [p for step, p in job.history]
    check(len(percents) == 6 and percents == sorted(percents) and percents[-1] == 100,
          f"progress seen: {percents}")
    check(bpy.context.window_manager.vdbturb_progress == 100, "the status bar's progress ends at 100%")
    check(not leftovers(out), f"temporary files left: {leftovers(out)}")
    with open(os.path.join(out, "vdbturb.log")) as log:
        text = log.read()
    check(f"{args.vdbturb} transfer --target" in text and "# done (exit 0)" in text, "the run's log")

    obj = addon.scene.result_object(domain)
    check(obj is not None and obj.type == 'VOLUME' and obj.parent == domain, "a Volume object parented to the domain")
    vol = obj.data
    check(vol.is_sequence and (vol.frame_start, vol.frame_duration, vol.frame_offset) == (3, 6, 2),
          f"sequence {vol.frame_start}+{vol.frame_duration} offset {vol.frame_offset}")
    check(domain.hide_render and obj.active_material.name == addon.scene.MATERIAL, "domain hidden, smoke material")
    scene = bpy.context.scene
    for frame, expect in ((5, "vdbturb_0005.vdb"), (2, None), (9, None)):
        scene.frame_set(frame)
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        grids = evaluated.grids
        grids.load()
        names = {g.name: g.data_type for g in grids}
        if expect:
            check(grids.frame_filepath.endswith(expect), f"frame {frame} reads {grids.frame_filepath}")
            check(names.get("density") == 'FLOAT' and names.get("vel") == 'VECTOR_FLOAT', f"grids {names}")
            check(evaluated.velocity_grid == "vel" and vol.velocity_unit == 'SECOND', "vel is the velocity grid, per second")
        else:
            check(not names, f"frame {frame} is outside the run but shows grids {names}")

    # Placement: the smoke stands on the emitter, which Blender placed in world space before the bake. The emitter
    # is off the domain's centre, so a turn or a scale taken wrongly moves the smoke away from it.
    lo, hi = density_box(args.vdbturb, os.path.join(out, "vdbturb_0008.vdb"), obj.matrix_world)
    centre = (lo + hi) / 2
    off = math.hypot(centre.x - emitter_at.x, centre.y - emitter_at.y)
    floor = (domain.matrix_world @ Vector((0, 0, -1))).z
    print(f"placement: smoke x,y centre {centre.x:.3f},{centre.y:.3f}, emitter {emitter_at.x:.3f},{emitter_at.y:.3f}"
          f" ({off:.3f} apart); smoke from z {lo.z:.3f}, floor {floor:.3f}, emitter bottom"
          f" {emitter_at.z - EMITTER_RADIUS:.3f}")
    # Measured 0.016 apart; half a cell wrong (0.088 apart) fails.
    check(off < CELL / 3, f"the smoke's centre is {off:.3f} from the emitter's axis (a cell is {CELL})")
    # Mantaflow keeps the wall's layer of cells empty: the smoke starts inside the first cell above the floor.
    check(floor + CELL / 4 < lo.z < emitter_at.z - EMITTER_RADIUS, f"the smoke starts at z {lo.z:.3f}")
    # The fallback for a domain not evaluated yet gives Blender's own lattice.
    evaluated = addon.scene.evaluated_lattice(domain, (24, 16, 32))
    check(evaluated is not None, "Blender's lattice of the evaluated domain")
    for got, want in zip(addon.scene.mesh_lattice(domain, (24, 16, 32)), evaluated):
        check((got - want).length < 1e-6, f"lattice from the mesh {got}, Blender's {want}")
    # Blender's own bounds of frame 8's grids hold the file's density box and stay inside the domain (half a cell
    # of slack for the edge cells).
    scene.frame_set(8)
    corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
    check(all(min(c[i] for c in corners) <= lo[i] + 1e-4 and max(c[i] for c in corners) >= hi[i] - 1e-4
              for i in range(3)), "Blender's bounds of the grids hold the density box")
    to_domain = domain.matrix_world.inverted()
    half = Vector(CELL / 2 / s for s in DOMAIN_SCALE)
    for corner in corners:
        p = to_domain @ corner
        check(all(abs(p[i]) <= 1 + half[i] + 1e-4 for i in range(3)), f"grid bounds leave the domain at {p}")
    return obj, seconds


def render(path):
    bpy.ops.render.render(write_still=True)
    shutil.copyfile(bpy.context.scene.render.filepath, path)
    image = bpy.data.images.load(path)
    pixels = list(image.pixels)
    bpy.data.images.remove(image)
    return pixels


def check_render(obj, emitter_at, work):
    scene = bpy.context.scene
    scene.frame_set(8)
    scene.render.engine = 'CYCLES'
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = 'CPU', 16, False
    scene.render.threads_mode, scene.render.threads = 'FIXED', 2
    scene.render.resolution_x = scene.render.resolution_y = 64
    scene.render.resolution_percentage, scene.render.dither_intensity = 100, 0
    scene.render.filepath = os.path.join(work, "render.png")
    scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.01, 0.01, 0.01)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
    sun.data.energy = 8
    sun.rotation_euler = (math.radians(40), 0, math.radians(30))
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    for thing in (sun, camera):
        scene.collection.objects.link(thing)
    scene.camera = camera
    look_at = emitter_at + Vector((0, 0, 0.5))
    camera.location = look_at + Vector((0, -4, 0.5))
    camera.rotation_euler = (look_at - camera.location).to_track_quat('-Z', 'Y').to_euler()
    with_smoke = render(os.path.join(work, "render_smoke.png"))
    obj.hide_render = True
    without = render(os.path.join(work, "render_empty.png"))
    obj.hide_render = False
    changed = sum(1 for i in range(0, len(without), 4)
                  if max(abs(with_smoke[i + c] - without[i + c]) for c in range(3)) > 0.02)
    rgb = [v for i, v in enumerate(without) if i % 4 != 3]
    spread = max(rgb) - min(rgb)
    print(f"render: {changed} of {len(without) // 4} pixels show smoke; without it the frame spans {spread:.3f}")
    check(changed > 200, f"only {changed} pixels differ with the smoke rendered")
    check(spread == 0, "without the smoke the frame is not the plain background: the domain rendered")
    return changed


def check_factor(addon, args, domain):
    settings = domain.vdbturb
    settings.factor, settings.frames = 2, "7-8"
    settings.output = os.path.join(args.work, "factor2")
    bpy.ops.vdbturb.check()
    check(settings.plan.startswith("factor 2: the source (factor 4) is box-downsampled first\nlattice, memory"),
          f"plan before the proxy exists: {settings.plan}")
    run, _ = run_blocking(addon)
    bpy.ops.vdbturb.check()
    check("\nratio 2\n" in settings.plan, f"plan once the proxy exists: {settings.plan}")
    check([s.argv[1] for s in run.job.steps] == ["resample", "transfer"], "factor 2 makes a source proxy first")
    check({step for step, _ in run.job.history} == {0, 1}, "progress from both steps")
    voxel = next(g["voxel_size"] for g in vdb_info(args.vdbturb, os.path.join(settings.output, "vdbturb_0008.vdb"))
                 ["grids"] if g["name"] == "density")
    check(abs(voxel - CELL / 2) < 1e-6, f"factor 2 gives voxel {voxel}, not {CELL / 2}")
    obj = addon.scene.result_object(domain)
    check((obj.data.frame_start, obj.data.frame_duration) == (7, 2), "the rerun updates the same Volume object")
    check(sum(1 for o in domain.children if o.type == 'VOLUME') == 1, "one Volume object per domain")
    settings.factor = 0


def check_cancel_and_resume(addon, args, domain):
    settings = domain.vdbturb
    settings.frames, settings.output = "1-10", os.path.join(args.work, "cancel")
    check(bpy.ops.vdbturb.run() == {'FINISHED'}, "run in the background")
    check(bpy.app.timers.is_registered(addon.ui.tick), "a timer follows the job")
    run = pump_until_first_frame(addon)
    check(bpy.ops.vdbturb.cancel() == {'FINISHED'}, "cancel")
    while addon.ui.tick():
        time.sleep(0.05)
    bpy.app.timers.unregister(addon.ui.tick)
    check(run.job.state == "cancelled" and run.job.returncode == 130,
          f"cancelled run: {run.job.state}, exit {run.job.returncode}")
    out = settings.output
    written = sorted(n for n in os.listdir(out) if n.startswith("vdbturb_0"))
    check(0 < len(written) < 10, f"written before the cancel: {written}")
    check(not leftovers(out), f"temporary files left: {leftovers(out)}")
    for name in written:  # whole frames: vdbturb reads every one
        vdb_info(args.vdbturb, os.path.join(out, name))
    check(addon.scene.result_object(domain).data.frame_start == 7, "a cancelled run imports nothing")
    print(f"cancel: {len(written)} whole frames kept, exit {run.job.returncode}")

    settings.resume = True
    run, _ = run_blocking(addon)
    settings.resume = False
    resumed = [f["frame"] for f in run.job.frames]
    check(resumed == list(range(len(written) + 1, 11)), f"resume wrote {resumed} after {written}")
    check(addon.scene.result_object(domain).data.frame_duration == 10, "the resumed run is imported")


def pump_until_first_frame(addon):
    """Background mode runs no timers: calls the add-on's timer function as Blender's event loop would."""
    run = addon.ui.current_run()
    deadline = time.monotonic() + 120
    while not run.job.frames and addon.ui.tick() and time.monotonic() < deadline:
        time.sleep(0.05)
    check(run.job.frames and run.job.running, "a frame written while the job still runs")
    return run


def check_file_load_cancels(addon, args, domain):
    settings = domain.vdbturb
    settings.frames, settings.output = "1-10", os.path.join(args.work, "load")
    check(bpy.ops.vdbturb.run() == {'FINISHED'}, "run in the background")
    run = pump_until_first_frame(addon)
    bpy.ops.wm.read_homefile(use_empty=True)  # the job's domain goes with its file
    while addon.ui.tick():
        time.sleep(0.05)
    check(run.job.state == "cancelled" and run.job.returncode == 130 and run.domain_name is None,
          f"after a file load: {run.job.state}, exit {run.job.returncode}, domain {run.domain_name}")


def check_bad_executable(addon, domain):
    prefs = bpy.context.preferences.addons["vdbturb_addon"].preferences
    prefs.executable = "/nonexistent/vdbturb"
    try:
        bpy.ops.vdbturb.run(wait=True)
        check(False, "a missing executable is refused")
    except RuntimeError as e:
        check("not an executable" in str(e), f"message: {e}")
    finally:
        prefs.executable = ""
    check(domain.vdbturb.status.startswith("error"), "the panel shows the error")


def main():
    started = time.monotonic()
    args = arguments()
    shutil.rmtree(args.work + "/run", ignore_errors=True)
    os.makedirs(args.work + "/run")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon = install(os.path.abspath(args.zip), args.work)
    cli = addon.cli
    exe, origin = cli.find_executable()
    check(os.path.samefile(exe, args.vdbturb) and origin.startswith("recorded"), f"executable {exe} from {origin}")
    check(cli.parse_frames("1001-1005x2,1010") == [1001, 1003, 1005, 1010], "frame list")
    domain, emitter_at = bake_domain(os.path.join(args.work, "run", "cache"))
    work = os.path.join(args.work, "run")
    args.work = work
    obj, seconds = check_run_and_import(addon, args, domain, emitter_at)
    print(f"run: 6 frames in {seconds:.1f} s")
    check_render(obj, emitter_at, work)
    check_factor(addon, args, domain)
    check_cancel_and_resume(addon, args, domain)
    check_bad_executable(addon, domain)
    check_file_load_cancels(addon, args, domain)  # last: it leaves an empty file
    print(f"test_addon: all checks passed in {time.monotonic() - started:.1f} s")


try:
    main()
except Exception:  # Blender would go on to exit 0; the test must fail
    traceback.print_exc()
    sys.stdout.flush()
    os._exit(1)
