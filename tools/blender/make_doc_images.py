"""The images of docs/blender_addon.md, written by Blender with a window (a screenshot needs one):

    BLENDER_USER_SCRIPTS=/tmp/w/scripts BLENDER_USER_CONFIG=/tmp/w/config \
    xvfb-run -a -s "-screen 0 1280x1500x24" blender --factory-startup --python tools/blender/make_doc_images.py -- \
        --zip build/vdbturb_addon.zip --data ../shared/data --work /tmp/w --out docs/img

Bakes the shared plume2 scene at 32^3 (30 frames), runs the add-on from its panel with blender-plume2-128 as the
source, takes a screenshot halfway (panel and status bar), then renders frame 30 of the domain's own smoke and of
the result with Cycles. About two minutes on two cores. Needs xvfb (apt-get install xvfb) where there is no display.
"""
import argparse
import math
import os
import shutil
import sys
import traceback

import bpy
from mathutils import Vector

FRAMES = 30
args = None
state = {"step": "setup"}


def arguments():
    parser = argparse.ArgumentParser()
    for name in ("zip", "data", "work", "out"):
        parser.add_argument("--" + name, required=True)
    parsed = parser.parse_args(sys.argv[sys.argv.index("--") + 1:])
    for name in ("zip", "data", "work", "out"):
        setattr(parsed, name, os.path.abspath(getattr(parsed, name)))
    return parsed


def window_context():
    win = bpy.context.window_manager.windows[0]
    return win, win.screen


def setup():
    """The plume2 scene (../shared/data/blender_plume_cube.py), baked, and a Properties editor beside the view."""
    bpy.ops.preferences.addon_install(filepath=args.zip, overwrite=True)
    bpy.ops.preferences.addon_enable(module="vdbturb_addon")
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, FRAMES
    cache = os.path.join(args.work, "plume32")
    shutil.rmtree(cache, ignore_errors=True)
    bpy.ops.mesh.primitive_cube_add(size=4)
    domain = bpy.context.active_object
    domain.name = "Smoke Domain"
    bpy.ops.object.modifier_add(type='FLUID')
    domain.modifiers["Fluid"].fluid_type = 'DOMAIN'
    ds = domain.modifiers["Fluid"].domain_settings
    ds.domain_type, ds.resolution_max = 'GAS', 32
    ds.cache_directory, ds.cache_type, ds.cache_data_format = cache, 'REPLAY', 'OPENVDB'
    ds.cache_frame_start, ds.cache_frame_end = 1, FRAMES
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0, 0, -1.5))
    emitter = bpy.context.active_object
    emitter.name = "Emitter"
    bpy.ops.object.modifier_add(type='FLUID')
    emitter.modifiers["Fluid"].fluid_type = 'FLOW'
    flow = emitter.modifiers["Fluid"].flow_settings
    flow.flow_type, flow.flow_behavior = 'SMOKE', 'INFLOW'
    emitter.hide_render = True
    for frame in range(1, FRAMES + 1):
        scene.frame_set(frame)
    domain.display_type = 'WIRE'
    bpy.context.view_layer.objects.active = domain
    domain.select_set(True)
    domain.vdbturb.source = os.path.join(args.data, "blender-plume2-128")
    domain.vdbturb.threads = 2

    win, screen = window_context()
    view = max((a for a in screen.areas if a.type == 'VIEW_3D'), key=lambda a: a.width)
    with bpy.context.temp_override(window=win, area=view):
        bpy.ops.screen.area_split(direction='VERTICAL', factor=0.45)
    props = max((a for a in screen.areas if a.type == 'VIEW_3D'), key=lambda a: a.x)
    props.type = 'PROPERTIES'  # its tabs exist once it has been drawn: start() picks Physics
    for area in screen.areas:
        if area.type == 'VIEW_3D':
            area.spaces.active.shading.type = 'SOLID'
            with bpy.context.temp_override(window=win, area=area, region=area.regions[-1]):
                bpy.ops.view3d.view_all()


def start():
    win, screen = window_context()
    props = next(a for a in screen.areas if a.type == 'PROPERTIES' and a.width > 300)
    props.spaces.active.context = 'PHYSICS'
    with bpy.context.temp_override(window=win, area=props):
        bpy.ops.vdbturb.check()
        bpy.ops.vdbturb.run()


def scroll_to_panel():
    """Scrolls the Physics tab to its end, where the add-on's panel comes after Blender's fluid panels."""
    win, screen = window_context()
    props = next(a for a in screen.areas if a.type == 'PROPERTIES' and a.width > 300)
    region = next(r for r in props.regions if r.type == 'WINDOW')
    with bpy.context.temp_override(window=win, area=props, region=region):
        for _ in range(6):
            bpy.ops.view2d.scroll_down(page=True)


def screenshot(name):
    win, _ = window_context()
    with bpy.context.temp_override(window=win):
        bpy.ops.wm.redraw_timer(type='DRAW_WIN_SWAP', iterations=1)
        bpy.ops.screen.screenshot(filepath=os.path.join(args.out, name))


def render(name, show_domain):
    scene = bpy.context.scene
    domain = bpy.data.objects["Smoke Domain"]
    result = next(o for o in domain.children if o.type == 'VOLUME')
    domain.hide_render, result.hide_render = not show_domain, show_domain
    if show_domain and not domain.data.materials:
        domain.data.materials.append(result.active_material)  # the same shader on Blender's own grids
    scene.render.filepath = os.path.join(args.out, name)
    bpy.ops.render.render(write_still=True)


def setup_render():
    scene = bpy.context.scene
    scene.frame_set(FRAMES)
    scene.render.engine = 'CYCLES'
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = 'CPU', 48, False
    scene.render.threads_mode, scene.render.threads = 'FIXED', 2
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 300, 400, 100
    scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.02, 0.02, 0.025)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
    sun.data.energy = 6
    sun.rotation_euler = (math.radians(50), 0, math.radians(-40))
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.lens = 100
    for thing in (sun, camera):
        scene.collection.objects.link(thing)
    scene.camera = camera
    camera.location = Vector((0, -12, -0.3))
    camera.rotation_euler = (Vector((0, 0, -0.7)) - camera.location).to_track_quat('-Z', 'Y').to_euler()


def step():
    """The timer that walks through the steps; Blender's own timers run the add-on's job meanwhile."""
    try:
        if state["step"] == "setup":
            setup()
            state["step"] = "start"
        elif state["step"] == "start":
            start()
            state["step"] = "halfway"
        elif state["step"] == "halfway":
            run = sys.modules["vdbturb_addon"].ui.current_run()
            if run.job.percent >= 50:
                scroll_to_panel()
                screenshot("blender-addon-panel.png")
                state["step"] = "done"
        elif state["step"] == "done":
            run = sys.modules["vdbturb_addon"].ui.current_run()
            if run.job.state != "running" and not bpy.app.timers.is_registered(
                    sys.modules["vdbturb_addon"].ui.tick):
                print("job:", run.job.state, run.job.error)
                setup_render()
                render("blender-addon-render-domain.png", True)
                render("blender-addon-render-vdbturb.png", False)
                sys.stdout.flush()
                os._exit(0)  # not quit_blender(): it would save a quit.blend
                return None
        return 0.5
    except Exception:
        traceback.print_exc()
        os._exit(1)


args = arguments()
os.makedirs(args.out, exist_ok=True)
bpy.context.preferences.view.show_splash = False
bpy.app.timers.register(step, first_interval=2.0)
