"""The smoke domain's cache and lattice, and the result as a Volume object placed on the domain."""
import os

import bpy
from mathutils import Matrix, Vector

MATERIAL = "vdbturb smoke"
OUT_KEY = "vdbturb_output"  # custom property marking the Volume object the add-on made for a domain


def domain_settings(obj):
    """The FluidDomainSettings of a smoke domain, else None."""
    if obj is None:
        return None
    for mod in obj.modifiers:
        if mod.type == 'FLUID' and mod.fluid_type == 'DOMAIN' and mod.domain_settings.domain_type == 'GAS':
            return mod.domain_settings
    return None


def cache_pattern(ds):
    """Where Blender writes the domain's grids (velocity, density...): the target of the transfer."""
    return os.path.join(bpy.path.abspath(ds.cache_directory), "data", "fluid_data_####.vdb")


def problems(ds):
    """What keeps vdbturb from reading this domain's cache, in the words of Blender's own panels."""
    found = []
    if ds.cache_data_format != 'OPENVDB':
        found.append("Cache > Format Volumes must be OpenVDB")
    if ds.use_adaptive_domain:
        # The adaptive domain moves its lattice from frame to frame; vdbturb wants one lattice per sequence.
        found.append("Adaptive Domain is on: vdbturb needs a fixed domain")
    return found


def evaluated_lattice(obj, base_res):
    """The domain's first cell corner and cell size in its object space, as Blender's fluid modifier set them;
    None before the domain has been evaluated at this resolution."""
    ds = domain_settings(obj.evaluated_get(bpy.context.evaluated_depsgraph_get()))
    if ds is None or tuple(ds.domain_resolution) != tuple(base_res) or not all(ds.cell_size):
        return None
    return Vector(ds.start_point), Vector(ds.cell_size)


def mesh_lattice(obj, base_res):
    """The same from the mesh's bounds split into the cache's cells (what the modifier computes)."""
    corners = [Vector(c) for c in obj.bound_box]
    lo = Vector(tuple(min(c[i] for c in corners) for i in range(3)))
    hi = Vector(tuple(max(c[i] for c in corners) for i in range(3)))
    return lo, Vector(tuple((hi[i] - lo[i]) / base_res[i] for i in range(3)))


def cache_to_object(obj, base_res, voxel):
    """The matrix from the cache's VDB world to the domain's object space.

    Mantaflow writes its grids with a plain scale transform (voxel = the domain's largest world extent over its
    resolution): cell i of the domain has its centre at i * voxel, whatever the domain's place, turn or scale.
    vdbturb's output keeps its target's world frame, so the same matrix places it.
    """
    p0, cell = evaluated_lattice(obj, base_res) or mesh_lattice(obj, base_res)
    scale = Matrix.Diagonal(Vector((cell.x / voxel, cell.y / voxel, cell.z / voxel, 1.0)))
    return Matrix.Translation(p0 + cell / 2) @ scale


def _renders_volume(mat):
    return mat is not None and mat.use_nodes and any(
        n.type == 'OUTPUT_MATERIAL' and n.inputs["Volume"].is_linked for n in mat.node_tree.nodes)


def smoke_material(domain):
    """The domain's own volume material (Quick Smoke's, say: vdbturb writes the same grid names), else one like it."""
    if _renders_volume(domain.active_material):
        return domain.active_material
    mat = bpy.data.materials.get(MATERIAL)
    if mat is not None:
        return mat
    mat = bpy.data.materials.new(MATERIAL)
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    shader = nodes.new("ShaderNodeVolumePrincipled")
    shader.location = (-300, 0)
    shader.inputs["Density Attribute"].default_value = "density"
    shader.inputs["Density"].default_value = 5.0  # as Blender's Quick Smoke
    mat.node_tree.links.new(shader.outputs["Volume"], out.inputs["Volume"])
    return mat


def result_object(domain):
    """The Volume object an earlier run made for this domain, if any."""
    return next((o for o in domain.children if o.type == 'VOLUME' and OUT_KEY in o), None)


def import_result(domain, first_file, frames, to_object, hide_domain):
    """The frames as a Volume sequence parented to the domain; a rerun updates the same object."""
    obj = result_object(domain)
    if obj is None:
        name = domain.name + " vdbturb"
        obj = bpy.data.objects.new(name, bpy.data.volumes.new(name))
        for coll in domain.users_collection or [bpy.context.scene.collection]:
            coll.objects.link(obj)
    vol = obj.data
    prefs = bpy.context.preferences.filepaths
    vol.filepath = bpy.path.relpath(first_file) if bpy.data.filepath and prefs.use_relative_paths else first_file
    vol.is_sequence = True
    vol.sequence_mode = 'CLIP'  # nothing outside the frames made (not the first or last frame held)
    # Blender reads file number (scene frame - frame_start + 1 + frame_offset): scene frame N reads file N.
    vol.frame_start = frames[0]
    vol.frame_duration = frames[-1] - frames[0] + 1
    vol.frame_offset = frames[0] - 1
    vol.velocity_unit = 'SECOND'  # vdbturb's vel (Blender finds it by name on load) is per second: motion blur
    if not vol.materials:
        vol.materials.append(smoke_material(domain))
    obj[OUT_KEY] = bpy.path.abspath(first_file)
    obj.parent = domain
    obj.matrix_parent_inverse = Matrix.Identity(4)
    obj.matrix_basis = to_object
    if hide_domain:
        domain.hide_render = True  # the domain's own low-res smoke would render over the result
    return obj
