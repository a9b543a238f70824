"""The add-on's import operator (File > Import > facegen animation); Blender only.

No `from __future__ import annotations` here: Blender reads the property annotations as objects.
"""

import bpy
from bpy.props import BoolProperty, FloatProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from .facegen_import import import_file


class FACEGEN_OT_import(bpy.types.Operator, ImportHelper):
    """Import a facegen animation with its frame rate, frame range and sound, or key ARKit weights (.json,
    .csv) onto a character's shape keys"""

    bl_idname = "facegen.import_animation"
    bl_label = "Import facegen animation"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012 (Blender reads it as a set)

    filter_glob: StringProperty(default="*.glb;*.gltf;*.usd;*.usda;*.usdc;*.usdz;*.json;*.csv",
                                options={"HIDDEN"})
    target: StringProperty(name="Target", description="ARKit weights (.json/.csv): the object whose "
                           "ARKit-named shape keys get them (empty: the active object)", default="")
    head: StringProperty(name="Head", description="ARKit weights with head motion: the object it turns (the "
                         "head or the character's root, about its origin; empty: not keyed)", default="")
    fps: FloatProperty(name="FPS", description="Frame rate when the file states none (0: the file's)",
                       default=0.0, min=0.0)
    sound: BoolProperty(name="Sound strip", description="Add the clip's sound (the WAV beside the file, else "
                        "the one inside it) as a sound strip", default=True)

    def execute(self, context):
        target = head = None
        if self.filepath.lower().endswith((".json", ".csv")):
            target = self.target or (context.active_object.name if context.active_object else None)
            head = self.head or None
        try:
            done = import_file(self.filepath, fps=self.fps or None, sound=self.sound, scene=context.scene,
                               target=target, head=head)
        except (OSError, RuntimeError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        for line in done["warnings"]:
            self.report({"WARNING"}, line)
        if done.get("unmatched"):
            self.report({"WARNING"}, f"no shape key for {len(done['unmatched'])} ARKit shapes: "
                        + ", ".join(done["unmatched"]))
        self.report({"INFO"}, f"facegen: {done['frames']} frames at {done['fps']:g} fps"
                    + (", with sound" if done["sound"] else ""))
        return {"FINISHED"}


def _menu(self, context) -> None:
    self.layout.operator(FACEGEN_OT_import.bl_idname, text="facegen animation (.glb/.gltf/.usd*/.json/.csv)")


def register() -> None:
    bpy.utils.register_class(FACEGEN_OT_import)
    bpy.types.TOPBAR_MT_file_import.append(_menu)


def unregister() -> None:
    bpy.types.TOPBAR_MT_file_import.remove(_menu)
    bpy.utils.unregister_class(FACEGEN_OT_import)
