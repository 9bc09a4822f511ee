"""The panel on a smoke domain, its settings, the Run/Check/Cancel operators and the progress in the status bar."""
import atexit
import hashlib
import os

import bpy
from bpy.props import BoolProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from . import cli, scene

OUT_NAME = "vdbturb_####.vdb"
_run = None  # the one job in flight (vdbturb uses every core; two at once would only share them)


class Run:
    """A job and what is needed to import its result once it is done."""

    def __init__(self, job, domain_name, out_pattern, frames, to_object, hide_domain):
        self.job, self.domain_name, self.out_pattern = job, domain_name, out_pattern
        self.frames, self.to_object, self.hide_domain = frames, to_object, hide_domain


def current_run():
    """The job in flight or last finished by the blocking path (scripts and tests read it)."""
    return _run


class VDBTURB_PG_settings(bpy.types.PropertyGroup):
    source: StringProperty(
        name="Source", subtype='FILE_PATH',
        description="High-res smoke cache whose turbulence is transferred: a folder, a frame pattern "
                    "(/path/fluid_data_####.vdb) or one of its frames")
    factor: IntProperty(
        name="Factor", min=0, max=16, default=0,
        description="Up-res factor. 0: the source's own (its voxel over the domain's). A divisor of that "
                    "(2 where the source gives 4) box-downsamples the source first (vdbturb resample)")
    frames: StringProperty(
        name="Frames", description="Domain frames, e.g. 1-100 or 1001-1100x2 (empty: the cache's frames on disk "
                                   "within the domain's cache range)")
    output: StringProperty(
        name="Output", subtype='DIR_PATH',
        description="Folder for the up-res frames (empty: vdbturb/ in the domain's cache directory)")
    threads: IntProperty(name="Threads", min=0, max=1024, default=0,
                         description="Worker threads (0: all cores); the result does not depend on it")
    source_offset: IntProperty(name="Source Offset", default=0,
                               description="Source frame = domain frame + this (--source-offset)")
    preroll: IntProperty(name="Preroll", min=0, default=0,
                         description="Run up to this many cache frames before the first one without writing them, so "
                                     "that the detail is established as in a longer run (--preroll)")
    resume: BoolProperty(
        name="Resume", default=False,
        description="Keep the frames a cancelled run with the same settings wrote and continue after them (--resume)")
    hide_domain: BoolProperty(name="Hide Domain in Renders", default=True,
                              description="Its own low-res smoke would render inside the result")
    status: StringProperty(name="Status")
    plan: StringProperty(name="Plan")


class VDBTURB_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    executable: StringProperty(
        name="vdbturb Executable", subtype='FILE_PATH',
        description="Empty: the vdbturb the add-on was built with, else vdbturb on PATH")

    def draw(self, context):
        self.layout.prop(self, "executable")
        try:
            path, origin = cli.find_executable(bpy.path.abspath(self.executable) if self.executable else "")
            self.layout.label(text=f"Runs {path} (from {origin})")
        except FileNotFoundError as e:
            self.layout.label(text=str(e), icon='ERROR')


def _executable():
    prefs = bpy.context.preferences.addons[__package__].preferences
    return cli.find_executable(bpy.path.abspath(prefs.executable) if prefs.executable else "")[0]


def _frames(ds, settings, target):
    """The domain frames to run, and their --frames text."""
    if settings.frames.strip():
        return cli.parse_frames(settings.frames), settings.frames.strip()
    on_disk = [f for f in cli.frames_on_disk(target) if ds.cache_frame_start <= f <= ds.cache_frame_end]
    if not on_disk:
        raise ValueError(f"no cache frames {ds.cache_frame_start}-{ds.cache_frame_end} in "
                         f"{os.path.dirname(target)}: bake the domain first")
    return on_disk, f"{on_disk[0]}-{on_disk[-1]}"


def _source_step(exe, settings, source, ratio, out_dir, fps):
    """The source to transfer from, and the resample step that makes it when the factor asks for a proxy."""
    natural = round(ratio)
    if settings.factor in (0, natural):
        return source, []
    down = natural / settings.factor
    if settings.factor > natural or abs(down - round(down)) > 1e-6:
        raise ValueError(f"factor {settings.factor}: the source gives {natural}; pick a divisor of it, or 0")
    down = round(down)
    # The proxy's folder names its source, so a new source never meets an old proxy (--skip-existing reuses one).
    tag = hashlib.sha1(source.encode()).hexdigest()[:8]
    proxy = os.path.join(out_dir, f"source_down{down}_{tag}", "source_####.vdb")
    argv = [exe, "resample", source, "--down", str(down), "--out", proxy, "--skip-existing", "--fps", fps,
            "--progress", "percent"]
    return proxy, [cli.Step(f"source proxy 1/{down}", argv)]


def plan(context, obj):
    """Everything a run needs, from the panel's settings; raises ValueError with a message for the user."""
    ds, settings = scene.domain_settings(obj), obj.vdbturb
    found = scene.problems(ds)
    if found:
        raise ValueError(found[0])
    if not settings.source.strip():
        raise ValueError("pick a source cache (a folder or a pattern)")
    exe = _executable()
    target = scene.cache_pattern(ds)
    frames, frames_text = _frames(ds, settings, target)
    source = cli.sequence_pattern(bpy.path.abspath(settings.source))
    source_frames = cli.frames_on_disk(source)
    if not source_frames:
        raise ValueError(f"source {source}: no frames on disk")
    target_info = cli.info(exe, cli.frame_path(target, frames[0]))
    voxel = cli.density_voxel(target_info)
    ratio = voxel / cli.density_voxel(cli.info(exe, cli.frame_path(source, source_frames[0])))
    out_dir = bpy.path.abspath(settings.output) if settings.output else os.path.join(os.path.dirname(
        os.path.dirname(target)), "vdbturb")
    render = context.scene.render
    fps = "%.10g" % (render.fps / render.fps_base)  # Blender caches record no frame rate; the scene knows it
    source_given = source
    source, steps = _source_step(exe, settings, source, ratio, out_dir, fps)
    out_pattern = os.path.join(out_dir, OUT_NAME)
    argv = [exe, "transfer", "--target", target, "--source", source, "--out", out_pattern, "--frames", frames_text,
            "--threads", str(settings.threads), "--target-fps", fps, "--source-fps", fps,
            "--json", "--progress", "percent"]
    if abs(ds.time_scale - 1) > 1e-6:  # Blender's frame is 0.1 x 25/fps time units, times the domain's time scale
        argv += ["--target-dt", "%g" % (2.5 / float(fps) * ds.time_scale)]
    if settings.source_offset:
        argv += ["--source-offset", str(settings.source_offset)]
    if settings.preroll:
        argv += ["--preroll", str(settings.preroll)]
    if settings.resume:
        argv.append("--resume")
    steps.append(cli.Step("transfer", argv))
    base_res = target_info.get("blender_base_resolution") or [0, 0, 0]
    if not all(base_res):
        raise ValueError(f"{cli.frame_path(target, frames[0])}: not a Blender cache (no base resolution)")
    to_object = scene.cache_to_object(obj, base_res, voxel)
    job = cli.Job(steps, os.path.join(out_dir, "vdbturb.log"))
    return Run(job, obj.name, out_pattern, frames, to_object, settings.hide_domain), ratio, source_given


def _poll_domain(context):
    obj = context.object
    return scene.domain_settings(obj) is not None and not (_run and _run.job.running)


class VDBTURB_OT_check(bpy.types.Operator):
    bl_idname = "vdbturb.check"
    bl_label = "Check"
    bl_description = "Check the caches and show the plan: factor, output lattice, memory and time (vdbturb --dry-run)"

    @classmethod
    def poll(cls, context):
        return _poll_domain(context)

    def execute(self, context):
        settings = context.object.vdbturb
        try:
            run, ratio, source = plan(context, context.object)
        except (ValueError, RuntimeError, FileNotFoundError) as e:
            settings.plan = ""
            self.report({'ERROR'}, str(e))
            return {'CANCELLED'}
        argv = run.job.steps[-1].argv
        proxy = argv[argv.index("--source") + 1]
        note = []
        if len(run.job.steps) > 1:
            note = [f"factor {settings.factor}: the source (factor {round(ratio)}) is box-downsampled first"]
            if not cli.frames_on_disk(proxy):
                # No proxy before the first run: check against the source, whose lattice and times do not apply.
                argv = list(argv)
                argv[argv.index("--source") + 1] = source
                note.append("lattice, memory and time: Check again once a run has made the proxy")
        ok, lines = cli.dry_run(argv)
        if ok and len(note) == 2:
            lines = [line for line in lines if line.startswith("warning")]
        settings.plan = "\n".join(note + lines)
        if not ok:
            self.report({'ERROR'}, lines[0])
            return {'CANCELLED'}
        return {'FINISHED'}


class VDBTURB_OT_run(bpy.types.Operator):
    bl_idname = "vdbturb.run"
    bl_label = "Run vdbturb"
    bl_description = ("Transfer the source's turbulence onto this domain's cache in the background, then import "
                      "the result as a Volume object on the domain")

    wait: BoolProperty(name="Wait", default=False, options={'HIDDEN', 'SKIP_SAVE'},
                       description="Block until done (scripts, tests and background mode, where timers never run)")

    @classmethod
    def poll(cls, context):
        return _poll_domain(context)

    def execute(self, context):
        global _run
        settings = context.object.vdbturb
        try:
            run = plan(context, context.object)[0]
            run.job.start()
        except (ValueError, RuntimeError, FileNotFoundError, OSError) as e:
            settings.status = f"error: {e}"
            self.report({'ERROR'}, str(e))
            return {'CANCELLED'}
        _run = run
        settings.status = "running"
        if not self.wait:
            bpy.app.timers.register(tick, first_interval=0.2, persistent=True)
            return {'FINISHED'}
        wm = context.window_manager
        wm.progress_begin(0, 100)
        run.job.wait(tick=lambda job: (wm.progress_update(job.percent), show_progress(job)))
        wm.progress_end()
        level, message = finish(run)
        self.report({level}, message)
        return {'FINISHED'} if run.job.state == "done" else {'CANCELLED'}


class VDBTURB_OT_cancel(bpy.types.Operator):
    bl_idname = "vdbturb.cancel"
    bl_label = "Cancel vdbturb"
    bl_description = "Stop vdbturb: the frames already written stay (whole), and Resume continues after them"

    @classmethod
    def poll(cls, context):
        return _run is not None and _run.job.running

    def execute(self, context):
        _run.job.cancel()
        self.report({'INFO'}, "vdbturb: cancelling")
        return {'FINISHED'}


def show_progress(job):
    """Puts the job's percent where the status bar and the panel read it, and redraws them when it moves."""
    wm = bpy.context.window_manager
    if round(wm.vdbturb_progress) != job.percent:
        wm.vdbturb_progress = job.percent
        redraw()


def redraw():
    """Redraws the Properties editors and the status bar (a property set from a timer redraws neither)."""
    for win in bpy.context.window_manager.windows:
        for area in win.screen.areas:
            if area.type == 'PROPERTIES':
                area.tag_redraw()
        if win.workspace is not None:
            # The status bar is no area of the screen; setting its text, here to none, is what redraws it.
            with bpy.context.temp_override(window=win):
                win.workspace.status_text_set_internal(None)


def tick():
    """The timer that follows a job started from the UI: polls it, shows its progress, imports when done."""
    if _run is None or _run.job.state not in ("running", "new"):
        return None
    _run.job.poll()
    show_progress(_run.job)
    if _run.job.running:
        return 0.25
    finish(_run)
    redraw()  # the status bar's progress goes
    return None


def finish(run):
    """Imports a finished job's frames, or says why not; returns (report level, message)."""
    job = run.job
    domain = bpy.data.objects.get(run.domain_name) if run.domain_name else None
    written = [f for f in run.frames if os.path.exists(cli.frame_path(run.out_pattern, f))]
    if job.state == "done" and domain is not None and written:
        obj = scene.import_result(domain, cli.frame_path(run.out_pattern, run.frames[0]), run.frames,
                                  run.to_object, run.hide_domain)
        level, message = 'INFO', f"vdbturb: {len(written)} frames imported as '{obj.name}'"
    elif job.state == "done":
        level, message = 'WARNING', f"vdbturb: done, nothing imported (frames in {os.path.dirname(run.out_pattern)})"
    elif job.state == "cancelled":
        level, message = 'WARNING', (f"vdbturb: cancelled after {len(job.frames)} new frames; they stay in "
                                     f"{os.path.dirname(run.out_pattern)} (Resume continues)")
    else:
        level, message = 'ERROR', f"vdbturb failed: {job.error} (log: {job.log_path})"
    print(message)
    if domain is not None:
        domain.vdbturb.status = message.replace("vdbturb: ", "")
    return level, message


def _cancel_on_load(_file):
    # The job's domain belongs to the file being closed: stop it rather than import into another file.
    if _run is not None and _run.job.running:
        _run.job.cancel()
        _run.domain_name = None


_cancel_on_load = bpy.app.handlers.persistent(_cancel_on_load)


def _cancel_at_exit():
    if _run is not None and _run.job.running:
        _run.job.cancel()
        _run.job.proc.wait(timeout=20)


class VDBTURB_PT_domain(bpy.types.Panel):
    bl_label = "vdbturb Up-res"
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "physics"

    @classmethod
    def poll(cls, context):
        return scene.domain_settings(context.object) is not None

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        obj = context.object
        ds, settings = scene.domain_settings(obj), obj.vdbturb
        for problem in scene.problems(ds):
            layout.label(text=problem, icon='ERROR')
        target = scene.cache_pattern(ds)
        frames = cli.frames_on_disk(target)
        col = layout.column()
        col.label(text=f"Target: {os.path.basename(target)}, "
                       + (f"frames {frames[0]}-{frames[-1]} on disk" if frames else "not baked"), icon='FILE_VOLUME')
        col.prop(settings, "source")
        col.prop(settings, "factor")
        col.prop(settings, "frames")
        col.prop(settings, "output")
        col.prop(settings, "threads")
        col.prop(settings, "source_offset")
        col.prop(settings, "preroll")
        col.prop(settings, "resume")
        col.prop(settings, "hide_domain")
        running = _run is not None and _run.job.running and _run.domain_name == obj.name
        if running:
            row = layout.row(align=True)
            row.prop(context.window_manager, "vdbturb_progress", text=_run.job.label, slider=True)
            row.operator("vdbturb.cancel", text="Cancel", icon='CANCEL')
        else:
            row = layout.row(align=True)
            row.operator("vdbturb.check", icon='VIEWZOOM')
            row.operator("vdbturb.run", icon='PLAY')
            if _run is not None and _run.job.running:
                layout.label(text=f"vdbturb is running for '{_run.domain_name}'", icon='INFO')
        box = None
        for line in filter(None, settings.plan.split("\n")):
            box = box or layout.box()
            box.label(text=line, icon='ERROR' if line.startswith("warning") else 'NONE')
        if settings.status and not running:
            layout.label(text=settings.status, icon='ERROR' if settings.status.startswith(("error", "vdbturb failed"))
                         else 'INFO')


def draw_status_bar(self, context):
    """vdbturb's progress and a Cancel button at the end of the status bar while a job runs."""
    if _run is None or not _run.job.running:
        return
    row = self.layout.row(align=True)
    row.label(text="vdbturb", icon='MOD_FLUID')
    row.prop(context.window_manager, "vdbturb_progress", text=_run.job.label, slider=True)
    row.operator("vdbturb.cancel", text="", icon='X')


CLASSES = (VDBTURB_PG_settings, VDBTURB_AP_preferences, VDBTURB_OT_check, VDBTURB_OT_run, VDBTURB_OT_cancel,
           VDBTURB_PT_domain)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.vdbturb = PointerProperty(type=VDBTURB_PG_settings)
    bpy.types.WindowManager.vdbturb_progress = FloatProperty(name="vdbturb Progress", subtype='PERCENTAGE',
                                                             min=0, max=100, precision=0)
    bpy.types.STATUSBAR_HT_header.append(draw_status_bar)
    bpy.app.handlers.load_pre.append(_cancel_on_load)
    atexit.register(_cancel_at_exit)


def unregister():
    _cancel_at_exit()
    atexit.unregister(_cancel_at_exit)
    if bpy.app.timers.is_registered(tick):
        bpy.app.timers.unregister(tick)
    if _cancel_on_load in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.remove(_cancel_on_load)
    bpy.types.STATUSBAR_HT_header.remove(draw_status_bar)
    del bpy.types.WindowManager.vdbturb_progress
    del bpy.types.Object.vdbturb
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
