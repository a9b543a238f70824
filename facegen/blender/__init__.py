"""Blender side of facegen: `facegen_import.py` (a script, a module), `facegen_arkit.py` (ARKit weights onto
shape keys by name) and this folder as an add-on.

As an add-on (`python -m facegen.blender.package` writes facegen_blender.zip, the package `facegen_blender`;
Blender > Preferences > Add-ons > Install from Disk) it adds File > Import > "facegen animation", which
imports through facegen_import.import_file: scene fps and frame range from the file, the clip's sound as a
sound strip, and for ARKit weights (.json, .csv) keys on the target object's ARKit-named shape keys.
Outside Blender (no bpy) importing this package does nothing.
"""

bl_info = {
    "name": "facegen animation import",
    "author": "facegen",
    "version": (0, 2, 0),
    "blender": (4, 2, 0),
    "location": "File > Import > facegen animation",
    "description": "Import facegen face animations (glTF, USD) with their fps, frame range and sound, "
                   "or ARKit weights (JSON, CSV) onto a character's shape keys",
    "category": "Import-Export",
}


def register() -> None:
    from . import addon

    addon.register()


def unregister() -> None:
    from . import addon

    addon.unregister()
