"""matex for Blender: textures the selected object from a text prompt with the matex program
(Make-A-Texture, multi-view). README "Blender add-on" walks through the panel."""

bl_info = {
    "name": "matex texture",
    "author": "matex",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "3D View > Sidebar > matex",
    "description": "Texture the selected object from a prompt with matex (Make-A-Texture)",
    "category": "Material",
}

from . import ops, panel, settings  # noqa: E402 (bl_info first, as Blender reads it)

_modules = (settings, ops, panel)


def register():
    for m in _modules:
        m.register()


def unregister():
    for m in reversed(_modules):
        m.unregister()
