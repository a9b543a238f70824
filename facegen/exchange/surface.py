"""The face's surface as every writer states it: texture coordinates and a plain skin material.

UVs are a cylindrical projection of the template around a vertical (y) axis behind it (at the bounding box's
middle in x, half its width behind its back in z, so every vertex is in front of the axis and the map has
no seam): u is the angle around that axis, v the height, each stretched to fill [0, 1] exactly. They depend
on the template only, so every frame, file and format of one face has the same UVs. The values are USD's
`st` (v up); glTF's TEXCOORD_0 has v down, so its writer flips v.

The material is a plain skin: base colour SKIN_COLOR (linear RGB), not metallic, roughness SKIN_ROUGHNESS
(glTF pbrMetallicRoughness, USD UsdPreviewSurface and displayColor).
"""

from __future__ import annotations

import numpy as np

SKIN_COLOR = (0.70, 0.42, 0.32)  # linear RGB (sRGB about 219, 174, 153)
SKIN_ROUGHNESS = 0.6
SKIN_METALLIC = 0.0
MATERIAL_NAME = "Skin"


def face_uvs(template: np.ndarray) -> np.ndarray:
    """[V, 2] float32 (u, v) in [0, 1]: the cylindrical projection of `template` (Y up, facing +Z)."""
    v = np.asarray(template, np.float64)
    low, high = v.min(0), v.max(0)
    axis_x, axis_z = (low[0] + high[0]) / 2, low[2] - (high[0] - low[0]) / 2
    angle = np.arctan2(v[:, 0] - axis_x, v[:, 2] - axis_z)  # 0 straight ahead (+z), + towards +x
    uv = np.stack([_stretch(angle), _stretch(v[:, 1])], axis=1)
    return np.clip(uv, 0.0, 1.0).astype(np.float32)


def _stretch(values: np.ndarray) -> np.ndarray:
    low, high = values.min(), values.max()
    return (values - low) / (high - low) if high > low else np.full_like(values, 0.5)
