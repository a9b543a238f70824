"""The Blender add-on as a zip to install (Preferences > Add-ons > Install from Disk): the helper modules of
this folder inside a package named `facegen_blender`, a module name no other add-on is likely to take.

    python -m facegen.blender.package [facegen_blender.zip]
"""

from __future__ import annotations

import os
import sys
import zipfile
from pathlib import Path

from facegen.atomic import atomic_path

ADDON_MODULE = "facegen_blender"
ADDON_FILES = ("__init__.py", "addon.py", "facegen_import.py", "facegen_arkit.py")


def write_addon(path: str | os.PathLike = f"{ADDON_MODULE}.zip") -> Path:
    """Write the add-on zip to `path`; returns it."""
    folder = Path(__file__).resolve().parent
    path = Path(path)
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in ADDON_FILES:
            archive.write(folder / name, f"{ADDON_MODULE}/{name}")
        # facegen_arkit.py loads ARKit's names and facegen's bounded reader of ARKit files from these files:
        # Blender's Python has no facegen to import
        archive.write(folder.parent / "arkit" / "names.py", f"{ADDON_MODULE}/arkit_names.py")
        archive.write(folder.parent / "exchange" / "arkit_read.py", f"{ADDON_MODULE}/arkit_read.py")
    return path


if __name__ == "__main__":
    print(write_addon(*sys.argv[1:2]))
