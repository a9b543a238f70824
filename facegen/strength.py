"""Region strengths (issue 24): `--strength lips=1.2,jaw=0.8,upper=1.5` scales the network's motion by
region: the lips (the community's lip region, where LVE is measured), the upper face (forehead, brows and
lids: the FDD region) and the jaw (the rest of the face: chin, cheeks, the jaw's skin). 1 is the model's own
motion, 0 holds that region at rest, up to MAX_STRENGTH.

Scales change smoothly across the regions' borders: each region's membership is blurred over the mesh
(`region_scales`: a few steps of neighbour averaging, about BLUR_CM wide), so a strong lip next to a calm
cheek never opens a crease. The layers over the network (blinks, gaze, emotion, head) are not scaled: they
have their own controls (--blink-rate, --emotion's intensity, --head-motion).
"""

from __future__ import annotations

import math

import numpy as np

from facegen.errors import FacegenError

REGIONS = ("lips", "jaw", "upper")
MAX_STRENGTH = 3.0
BLUR_CM = 0.8  # how wide the change from one region's strength to the next is


def parse_strength(value) -> dict[str, float] | None:
    """"lips=1.2,jaw=0.8,upper=1.5" (any of the three, in any order) or a dict as {region: scale}; None or
    every scale 1: None (the model's motion as it is)."""
    if value is None or value == "":
        return None
    if isinstance(value, dict):
        pairs = list(value.items())
    elif isinstance(value, str):
        pairs = []
        for part in value.split(","):
            name, eq, number = part.partition("=")
            if not eq:
                raise FacegenError(f"strength {part.strip()!r} is not REGION=SCALE: write e.g. "
                                   "lips=1.2,jaw=0.8,upper=1.5", param="strength")
            try:
                pairs.append((name.strip(), float(number)))
            except ValueError:
                raise FacegenError(f"strength {part.strip()!r}: {number.strip()!r} is not a number: "
                                   "write e.g. lips=1.2", param="strength") from None
    else:
        raise FacegenError(f"strength must be a string such as 'lips=1.2,jaw=0.8' or a dict, got "
                           f"{value!r}", param="strength")
    out: dict[str, float] = {}
    for name, scale in pairs:
        if name not in REGIONS:
            raise FacegenError(f"unknown strength region {name!r}: use {', '.join(REGIONS)}",
                               param="strength")
        number = isinstance(scale, int | float) and not isinstance(scale, bool)
        if not number or not math.isfinite(scale) or not 0 <= scale <= MAX_STRENGTH:
            raise FacegenError(f"the {name} strength must be a number from 0 (at rest) to {MAX_STRENGTH:g} "
                               f"(1: the model's motion), got {scale!r}", param="strength")
        if name in out:
            raise FacegenError(f"strength {name} is given twice", param="strength")
        out[name] = float(scale)
    return None if all(v == 1.0 for v in out.values()) else {r: out.get(r, 1.0) for r in REGIONS}


def as_text(strength: dict[str, float] | None) -> str:
    """The command-line form of a parsed strength ("" for none)."""
    return ",".join(f"{r}={strength[r]:g}" for r in REGIONS) if strength else ""


def region_scales(mesh, strength: dict[str, float]) -> np.ndarray:
    """The scale of each vertex of `mesh` [V] float32 for `strength` (see the module docstring). A mesh
    without the lip and upper-face regions cannot be scaled by region: a FacegenError."""
    from facegen.face.regions import LIPS, UPPER_FACE

    missing = [r for r in (LIPS, UPPER_FACE) if r not in mesh.regions]
    if missing:
        raise FacegenError(f"--strength needs the face's {' and '.join(missing)} region(s) (regions/lve.txt "
                           "and regions/fdd.txt beside a template): this face has none", param="strength")
    lips = _blurred(mesh, mesh.regions[LIPS])
    upper = _blurred(mesh, mesh.regions[UPPER_FACE]) * (1 - lips)
    jaw = 1 - lips - upper
    scales = strength["lips"] * lips + strength["upper"] * upper + strength["jaw"] * jaw
    return scales.astype(np.float32)


def _blurred(mesh, indices) -> np.ndarray:
    """The region's indicator averaged over neighbouring vertices until it changes over about BLUR_CM."""
    import scipy.sparse as sp

    from facegen.face.rig import face_scale

    vertices = np.asarray(mesh.vertices, np.float64)
    faces = np.asarray(mesh.faces, np.int64)
    n = len(vertices)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    adjacency = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    adjacency = ((adjacency + adjacency.T) > 0).astype(np.float64) + sp.identity(n)
    step = sp.diags(1 / np.asarray(adjacency.sum(1)).ravel()) @ adjacency
    length = float(np.median(np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)))
    try:
        cm = face_scale(vertices, mesh.regions)[1]
    except (KeyError, ValueError, np.linalg.LinAlgError):
        cm = float(np.ptp(vertices[:, 1])) / 20.0  # a face is about 20 cm high
    # a random walk spreads sqrt(steps) edges: enough steps to spread BLUR_CM / 2 each way
    steps = int(np.clip((0.5 * BLUR_CM * cm / max(length, 1e-12)) ** 2, 1, 400))
    out = np.zeros(n)
    out[np.asarray(indices, np.int64)] = 1.0
    for _ in range(steps):
        out = step @ out
    return out
