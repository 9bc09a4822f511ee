"""vdbturb in Blender: a smoke domain's OpenVDB cache up-res'd by `vdbturb transfer` (docs/blender_addon.md)."""

bl_info = {
    "name": "vdbturb: Turbulence Transfer",
    "author": "vdbturb",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Physics > vdbturb Up-res (on a smoke domain)",
    "description": "Adds a high-res simulation's turbulence to a smoke domain's OpenVDB cache with vdbturb "
                   "transfer, in the background, and imports the result as a Volume",
    "category": "Physics",
}

from . import ui  # noqa: E402 (bl_info comes first: Blender reads it without importing the add-on)


def register():
    ui.register()


def unregister():
    ui.unregister()
