"""A steady, textured Blender plume: the roughly stationary example that Okabe et al.'s method assumes
(`vdbturb animate`, bench/animate_quality.sh stationary). The shared blender-plume caches are start-ups: a blob
that grows, whose rendered density does not move with the fluid. This one emits density from a scrolling
Clouds texture with vorticity confinement and dissolves it, so that after about frame 60 a textured column
rises steadily through the 4x4x4 domain (the layout of ../shared/data/blender_plume_cube.py).

blender -b --factory-startup --python blender_plume_textured.py -- RES OUTDIR FRAMES
"""
import bpy, sys, time
argv = sys.argv[sys.argv.index("--") + 1:]
res, out, frames = int(argv[0]), argv[1], int(argv[2])
bpy.ops.wm.read_factory_settings(use_empty=True)
sc = bpy.context.scene
sc.frame_start, sc.frame_end = 1, frames
bpy.ops.mesh.primitive_cube_add(size=4, location=(0, 0, 0))
dom = bpy.context.active_object
bpy.ops.object.modifier_add(type='FLUID')
dom.modifiers["Fluid"].fluid_type = 'DOMAIN'
ds = dom.modifiers["Fluid"].domain_settings
ds.domain_type = 'GAS'; ds.resolution_max = res
ds.vorticity = 0.3
ds.use_dissolve_smoke = True; ds.dissolve_speed = 20
ds.cache_directory = out; ds.cache_type = 'REPLAY'; ds.cache_data_format = 'OPENVDB'
ds.cache_frame_start, ds.cache_frame_end = 1, frames
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0, 0, -1.5))
e = bpy.context.active_object
bpy.ops.object.modifier_add(type='FLUID')
e.modifiers["Fluid"].fluid_type = 'FLOW'
fs = e.modifiers["Fluid"].flow_settings
fs.flow_type = 'SMOKE'; fs.flow_behavior = 'INFLOW'
tex = bpy.data.textures.new("puffs", type='CLOUDS')
tex.noise_scale = 0.15
fs.use_texture = True; fs.noise_texture = tex; fs.texture_map_type = 'AUTO'; fs.texture_size = 1.0
# Scroll the texture so that the emitted density varies in time as well as in space.
fs.texture_offset = 0.0
fs.keyframe_insert("texture_offset", frame=1)
fs.texture_offset = float(frames) * 0.05
fs.keyframe_insert("texture_offset", frame=frames)
bpy.context.view_layer.objects.active = dom
t = time.time()
for f in range(1, frames + 1):
    sc.frame_set(f)
print("BAKE_SECONDS %.2f frames %d res %d" % (time.time() - t, frames, res))
