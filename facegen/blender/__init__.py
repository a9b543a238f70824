"""Blender side of facegen: `facegen_import.py` (a script, a module) and this folder as an add-on.

As an add-on (zip this folder, Blender > Preferences > Add-ons > Install from Disk) it adds
File > Import > "facegen animation (.glb/.gltf/.usd*)", which imports through facegen_import.import_file:
scene fps and frame range from the file, and the WAV beside it as a sound strip.
Outside Blender (no bpy) importing this package does nothing.
"""

bl_info = {
    "name": "facegen animation import",
    "author": "facegen",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "File > Import > facegen animation",
    "description": "Import facegen face animations (glTF, USD) with their fps, frame range and sound",
    "category": "Import-Export",
}


def register() -> None:
    from . import addon

    addon.register()


def unregister() -> None:
    from . import addon

    addon.unregister()
