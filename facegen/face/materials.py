"""The face's materials, one table for every route: the USD and glTF writers (UsdPreviewSurface, glTF PBR)
and the rasteriser of `--preview` and `facegen render` read the same colours, so a DCC and facegen's own
pictures show the same face.

Colours are linear RGB (what UsdPreviewSurface's diffuseColor and glTF's baseColorFactor hold); `srgb`
gives the display values the rasteriser starts from. Which face vertices wear which material is
`face_materials` (the skin's regions: lips, eye whites, the mouth's inside; the lips' edge blended over a
few millimetres by `lip_blend`); the parts (facegen.face.parts) name their own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Material:
    """A plain PBR surface: `name` (the prim / glTF material name), linear `color`, `roughness`."""

    name: str
    color: tuple[float, float, float]
    roughness: float
    metallic: float = 0.0

    @property
    def srgb(self) -> tuple[float, float, float]:
        c = np.asarray(self.color, np.float64)
        s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
        return tuple(float(x) for x in s)


MATERIALS: dict[str, Material] = {m.name: m for m in (
    Material("Skin", (0.70, 0.42, 0.32), 0.6),
    Material("Lips", (0.48, 0.16, 0.15), 0.45),
    Material("EyeWhite", (0.83, 0.82, 0.78), 0.2),
    Material("Iris", (0.12, 0.22, 0.30), 0.25),
    Material("Pupil", (0.005, 0.005, 0.006), 0.1),
    Material("Teeth", (0.80, 0.76, 0.64), 0.3),
    Material("Tongue", (0.50, 0.13, 0.13), 0.5),
    Material("MouthInterior", (0.10, 0.022, 0.022), 0.7),
    Material("Conjunctiva", (0.58, 0.26, 0.23), 0.35),  # the eye sockets' lining (facegen.face.parts)
)}
SKIN = "Skin"
# the face's regions that wear another material than skin (facegen.face.regions' names)
REGION_MATERIALS = {"lips": "Lips", "left_eyeball": "EyeWhite", "right_eyeball": "EyeWhite",
                    "mouth_cavity": "MouthInterior"}


def face_materials(regions: dict[str, np.ndarray], num_vertices: int) -> dict[str, np.ndarray]:
    """{material name: the face's triangle-free vertex indices wearing it} for the regions the face names
    (skin: the rest); empty when it names none of REGION_MATERIALS."""
    owner = np.full(num_vertices, SKIN, dtype=object)
    named = False
    for region, material in REGION_MATERIALS.items():
        if region in regions:
            idx = np.asarray(regions[region], np.int64)
            owner[idx[(idx >= 0) & (idx < num_vertices)]] = material
            named = True
    if not named:
        return {}
    return {name: np.flatnonzero(owner == name) for name in MATERIALS if np.any(owner == name)}


def face_triangle_materials(faces: np.ndarray, regions: dict[str, np.ndarray],
                            num_vertices: int) -> dict[str, np.ndarray]:
    """{material name: triangle indices} of the face (USD GeomSubsets): a triangle wears the material most
    of its corners wear (skin on a tie with skin)."""
    by_vertex = face_materials(regions, num_vertices)
    if not by_vertex:
        return {}
    names = list(by_vertex)
    code = np.zeros(num_vertices, np.int64)
    for k, name in enumerate(names):
        code[by_vertex[name]] = k
    corners = code[np.asarray(faces, np.int64)]
    counts = np.stack([(corners == k).sum(1) for k in range(len(names))], 1)
    best = counts.argmax(1)
    best[counts.max(1) < 2] = names.index(SKIN) if SKIN in names else best[counts.max(1) < 2]
    return {name: np.flatnonzero(best == k).astype(np.int32) for k, name in enumerate(names)
            if np.any(best == k)}


def face_colors(faces: np.ndarray, regions: dict[str, np.ndarray], num_vertices: int) -> np.ndarray | None:
    """Per-vertex sRGB colours [V, 3] of the face from its materials, the lips' edge blended into the skin
    by `lip_blend` (a smooth boundary, not a jagged one); None when the face names no material region."""
    by_vertex = face_materials(regions, num_vertices)
    if not by_vertex:
        return None
    colors = np.empty((num_vertices, 3), np.float32)
    for name, idx in by_vertex.items():
        colors[idx] = MATERIALS[name].srgb
    if "Lips" in by_vertex:
        w = lip_blend(faces, by_vertex["Lips"], num_vertices)[:, None]
        skin = np.asarray(MATERIALS[SKIN].srgb, np.float32)
        lips = np.asarray(MATERIALS["Lips"].srgb, np.float32)
        soft = (w > 0) & (w < 1)
        colors[soft[:, 0]] = (skin + w * (lips - skin))[soft[:, 0]]
    return colors


def srgb_to_linear(rgb) -> np.ndarray:
    """Linear RGB float32 of sRGB display values (the inverse of `Material.srgb`)."""
    c = np.asarray(rgb, np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def lip_blend(faces: np.ndarray, lips: np.ndarray, num_vertices: int, rings: int = 3) -> np.ndarray:
    """How much of the lips' colour each vertex takes, [V] in [0, 1]: 1 inside the lips, 0 outside, and a
    smooth ramp over `rings` rings of neighbours across the lips' edge (neighbour averaging)."""
    f = np.asarray(faces, np.int64)
    w = np.zeros(num_vertices)
    w[lips] = 1.0
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    degree = (np.bincount(edges[:, 0], minlength=num_vertices)
              + np.bincount(edges[:, 1], minlength=num_vertices))
    for _ in range(rings):
        total = np.bincount(edges[:, 0], w[edges[:, 1]], num_vertices) + np.bincount(
            edges[:, 1], w[edges[:, 0]], num_vertices)
        w = 0.5 * w + 0.5 * total / np.maximum(degree, 1)
    return np.clip(w, 0.0, 1.0)
