"""What a picture of an animation draws: the face and the parts beside it (facegen.face.parts: eyes with
irises and pupils, teeth, tongue) as one triangle set, coloured from the one materials table
(face/materials.py) that the USD and glTF writers use, so `--preview`, `facegen render` and a DCC agree."""

from __future__ import annotations

import numpy as np

from facegen.animation import Animation
from facegen.face.materials import MATERIALS, face_colors

# The mouth's inside as a picture shows it. The rasteriser lights every surface alike, so the cavity's own
# colour (MouthInterior, a dark red) came out lit; behind the lips a real mouth, and a DCC render of facegen's
# file with its occlusion, is nearly black. A face tracker (MediaPipe) took the lit cavity for lip and read a
# mouth open by 5 mm as closed (docs/real_faces.md). The materials (USD, glTF) keep the surface's own colour.
CAVITY_SHADE = 0.12  # the cavity's sRGB colour times this: (0.04, 0.02, 0.02)


def picture_colors(faces: np.ndarray, regions: dict, num_vertices: int) -> np.ndarray | None:
    """Per-vertex sRGB colours [V, 3] of the face as facegen's pictures draw it: its materials
    (face_colors), the mouth cavity in shadow (CAVITY_SHADE); None when the face names no material region."""
    colors = face_colors(faces, regions, num_vertices)
    if colors is not None and "mouth_cavity" in regions:
        cavity = np.asarray(regions["mouth_cavity"], np.int64)
        cavity = cavity[(cavity >= 0) & (cavity < num_vertices)]
        colors[cavity] *= CAVITY_SHADE
    return colors


class Scene:
    """The face of `anim` and, with `parts`, its parts: `faces` and `template` for the Renderer, per-vertex
    sRGB `colors` (None: the renderer's skin), `points(face_points, t)` every vertex of frame t."""

    def __init__(self, anim: Animation, parts: bool = True) -> None:
        self.tracks = anim.part_meshes() if parts else []
        faces, template = [np.asarray(anim.faces, np.int32)], [np.asarray(anim.template, np.float32)]
        colors = picture_colors(anim.faces, anim.regions, anim.num_vertices)
        tinted = [colors] if colors is not None else [np.tile(np.float32(MATERIALS["Skin"].srgb),
                                                              (anim.num_vertices, 1))]
        count = anim.num_vertices
        for track in self.tracks:
            part = track.part
            faces.append(part.faces.astype(np.int32) + count)
            template.append(track.points(0).astype(np.float32))
            tinted.append(np.array([MATERIALS[m].srgb for m in part.vertex_materials()], np.float32))
            count += len(part.vertices)
        self.faces = np.concatenate(faces)
        self.template = np.concatenate(template)
        self.colors = np.concatenate(tinted) if (colors is not None or self.tracks) else None

    def points(self, face_points: np.ndarray, t: int) -> np.ndarray:
        """Frame t's vertices: the face's (`face_points`, face-local) and the parts' after them."""
        if not self.tracks:
            return face_points
        return np.concatenate([np.asarray(face_points, np.float32)]
                              + [tr.points(t).astype(np.float32) for tr in self.tracks])
