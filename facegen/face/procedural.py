"""A procedural neutral face with BIWI's vertex count (23,370), named regions and per-speaker shapes.

The face is built in centimetres and normalised like BIWI (mean vertex at the origin, total surface area
1; Y up, looking +Z). It has three parts:

* the skin: a 123 x 176 grid (columns wrap around the head like a mask, rows run chin → forehead) whose
  depth is a sum of anatomical features (nose, brows, cheeks, lips, chin, ...). The mouth and the two eyes
  are slits in the grid: between two neighbouring rows the triangles are left out, so the upper and lower
  lip (lid) are separate vertices that can part and meet. A smooth vertical warp opens the eye slits into
  almond-shaped openings; the lids drape over the eyeballs.
* two eyeballs (ellipsoid caps behind the eye openings);
* a mouth cavity (teeth wall and throat) behind the lips, seen when the mouth opens.

Regions (vertex index arrays) name what the rig moves: `lips`, `jaw`, `upper_face`, `brows`, `forehead`,
`upper_lids`, `lower_lids`, `cheeks`, `nose`, eyeballs, the mouth cavity and the ordered slit margins.
"Left" is the subject's left (+X). The shape in centimetres (parameters, landmarks, anatomy) is in
facegen.face.anatomy; the committed neutral face's files in facegen.face.template.
"""

from __future__ import annotations

import functools

import numpy as np

from facegen.face.anatomy import (
    EYE_Y,
    LAYOUT,
    MOUTH_Y,
    PHI_MAX,
    FaceParams,
    cross_section,
    drape,
    eye_shape,
    eyeball_centre_z,
    fade_sides,
    features,
    lid_crease,
    lip_borders,
    profile,
    skin_depth,
    speaker_params,
    speaker_warp,
)
from facegen.face.mesh import Mesh, unit_area

NUM_VERTICES = 23370
GRID_COLUMNS, GRID_ROWS = 123, 176  # skin grid
ROWS_BELOW_MOUTH, ROWS_BETWEEN_SLITS = 52, 64  # the rest (60) lie above the eye slit
EYE_RINGS, EYE_SEGMENTS = 13, 40  # eyeball cap: a pole and 13 rings of 40
CAVITY_COLUMNS, CAVITY_ROWS = 40, 17  # mouth cavity grid
BOTTOM_V, TOP_V = -12.6, 10.0  # arc-length extent of the rows (cm)


# --------------------------------------------------------------------------------------------- the grid
def _section(a: float, b: float, first: float, n: int, last: float) -> np.ndarray:
    """n row positions in [a, b], denser near the mouth and the eyes: with F the (scaled) integral of
    the row density from a, row k sits where F = first + k, and F(b) = first + n - 1 + last."""
    v = np.linspace(a, b, 4001)
    rho = 1.0 + 0.9 * np.exp(-(((v - MOUTH_Y) / 1.6) ** 2)) + 0.8 * np.exp(-(((v - EYE_Y) / 1.5) ** 2))
    cum = np.concatenate([[0.0], np.cumsum((rho[1:] + rho[:-1]) / 2 * np.diff(v))])
    cum *= (first + n - 1 + last) / cum[-1]
    return np.interp(first + np.arange(n), cum, v)


def _material_rows() -> np.ndarray:
    """Row positions along the vertical arc length v (cm); the slits lie half-way between two rows."""
    n_top = GRID_ROWS - ROWS_BELOW_MOUTH - ROWS_BETWEEN_SLITS
    below = _section(BOTTOM_V, MOUTH_Y, 0.0, ROWS_BELOW_MOUTH, 0.5)
    between = _section(MOUTH_Y, EYE_Y, 0.5, ROWS_BETWEEN_SLITS, 0.5)
    above = _section(EYE_Y, TOP_V, 0.5, n_top, 0.0)
    return np.concatenate([below, between, above])


def _material_columns() -> np.ndarray:
    u = np.linspace(-1.0, 1.0, GRID_COLUMNS)
    beta = 0.28
    return PHI_MAX * (u * (1 - beta) + beta * u**3)


# ----------------------------------------------------------------------------------------------- slits
def _slit_warp(x: np.ndarray, v: np.ndarray, cols: np.ndarray, p: FaceParams) -> tuple[np.ndarray, dict]:
    """Vertical offsets that open the eye slits and close the mouth slit to its rest gap.

    Returns the offsets for the grid [H, W] and the slit column sets {"mouth", "eyes"} (column indices).
    """
    L = LAYOUT
    rows = _material_rows()
    i_m = ROWS_BELOW_MOUTH - 1  # the slit lies between rows i_m and i_m + 1
    i_e = ROWS_BELOW_MOUTH + ROWS_BETWEEN_SLITS - 1
    ax = np.abs(x)
    dy = np.zeros_like(x)
    slits = {}
    for name, i0, y0 in (("mouth", i_m, MOUTH_Y), ("eyes", i_e, EYE_Y)):
        row_gap = rows[i0 + 1] - rows[i0]
        axr = ax[i0]  # |x| of the columns on the lower slit row
        if name == "mouth":
            s = np.clip(axr / L.mouth_half_width, -2, 2)
            in_slit = np.abs(s) < 1.0
            s_all = ax / L.mouth_half_width
            inside = np.clip(1 - s_all**2, 0, 1)
            up, low = L.mouth_open * inside**0.5, L.mouth_open * inside**0.5
            sig_up, sig_low = 0.45, 0.45
        else:
            s, _, _ = eye_shape(axr, p)
            in_slit = np.abs(s) < 1.0
            _, up, low = eye_shape(ax, p)
            sig_up, sig_low = 0.95, 0.75
        # closing term: 1 inside the slit, 0.85 at its end columns, fading out over 3 columns
        j = np.arange(len(cols))
        slit_cols = np.nonzero(in_slit)[0]
        dist = np.min(np.abs(j[:, None] - slit_cols[None, :]), axis=1)
        close = np.interp(dist, [0, 1, 2, 3, 4], [1.0, 0.6, 0.3, 0.1, 0.0])
        ends = np.concatenate([slit_cols[:1], slit_cols[-1:], *(
            slit_cols[np.nonzero(np.diff(slit_cols) > 1)[0] + k] for k in (0, 1))])
        close[ends] = 0.85
        for side, sig, opening in ((+1, sig_up, up), (-1, sig_low, low)):
            mask = (v > y0) if side > 0 else (v < y0)
            d = np.abs(v - y0) - row_gap / 2
            g = np.exp(-((np.maximum(d, 0) / sig) ** 2))
            amount = opening - close[None, :] * row_gap / 2
            dy += np.where(mask, side * amount * g, 0.0)
        slits[name] = slit_cols
    return dy, slits


# ---------------------------------------------------------------------------------- topology helpers
def _grid_faces(slits: dict) -> np.ndarray:
    """Triangles of the skin grid, mirrored diagonals, without the quads of the slits."""
    H, W = GRID_ROWS, GRID_COLUMNS
    i, j = np.meshgrid(np.arange(H - 1), np.arange(W - 1), indexing="ij")
    keep = np.ones_like(i, dtype=bool)
    i_m = ROWS_BELOW_MOUTH - 1
    i_e = ROWS_BELOW_MOUTH + ROWS_BETWEEN_SLITS - 1
    for row, cols in ((i_m, slits["mouth"]), (i_e, slits["eyes"])):
        cs = {int(c) for c in cols}
        for c in range(W - 1):
            if c in cs and c + 1 in cs:
                keep[row, c] = False
    i, j = i[keep], j[keep]
    a = i * W + j
    b = a + 1
    c = a + W + 1
    d = a + W
    left = j < (W - 1) // 2
    t1 = np.where(left[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
    t2 = np.where(left[:, None], np.stack([b, c, d], 1), np.stack([a, c, d], 1))
    return np.concatenate([t1, t2]).astype(np.int32)


def _cap(rings: int, segments: int, theta_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit sphere cap around +Z: (theta, psi) per vertex and outward triangles."""
    theta, psi = [0.0], [0.0]
    for k in range(1, rings + 1):
        for m in range(segments):
            theta.append(theta_max * k / rings)
            psi.append(2 * np.pi * m / segments)
    faces = []
    for m in range(segments):
        faces.append([0, 1 + m, 1 + (m + 1) % segments])
    for k in range(rings - 1):
        base0, base1 = 1 + k * segments, 1 + (k + 1) * segments
        for m in range(segments):
            n = (m + 1) % segments
            faces.append([base0 + m, base1 + m, base1 + n])
            faces.append([base0 + m, base1 + n, base0 + n])
    return np.stack([np.array(theta), np.array(psi)], 1), np.array(faces, np.int32)


# ---------------------------------------------------------------------------------------- construction
def _skin(p: FaceParams) -> tuple[np.ndarray, np.ndarray, dict, dict]:
    rows = _material_rows()
    cols = _material_columns()
    v = np.repeat(rows[:, None], GRID_COLUMNS, 1)
    phi = np.repeat(cols[None, :], GRID_ROWS, 0)
    y, zb = profile(v, p)
    x, zc = cross_section(phi, v)
    dy, slits = _slit_warp(x, v, cols, p)
    y = y + dy
    z = zb + zc + features(x, y, p) * fade_sides(phi)
    z = drape(x, y, z, p)
    z += lid_crease(x, y, p)
    pts = np.stack([x, y, z], -1).reshape(-1, 3)
    info = {"v": v.reshape(-1), "x": x.reshape(-1), "y": y.reshape(-1), "phi": phi.reshape(-1)}
    return pts, _grid_faces(slits), slits, info


def _eyeballs(p: FaceParams) -> tuple[np.ndarray, np.ndarray]:
    L = LAYOUT
    tp, faces = _cap(EYE_RINGS, EYE_SEGMENTS, np.radians(88))
    th, ps = tp[:, 0], tp[:, 1]
    unit = np.stack([L.eyeball_a * np.sin(th) * np.cos(ps), L.eyeball_b * np.sin(th) * np.sin(ps),
                     L.eyeball_b * np.cos(th)], 1)
    zc = eyeball_centre_z(p)
    pts, tris = [], []
    for k, side in enumerate((+1, -1)):  # left (+x) then right
        pts.append(unit + np.array([side * L.eye_x, EYE_Y, zc]))
        tris.append(faces + k * len(unit))  # a translated cap keeps its outward winding
    return np.concatenate(pts), np.concatenate(tris)


def _cavity(p: FaceParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mouth cavity behind the lips: teeth walls near the lips, a throat behind. Returns the points,
    triangles (facing +Z) and the across/vertical coordinates (s, t) of each vertex."""
    L = LAYOUT
    s = np.linspace(-1, 1, CAVITY_COLUMNS)
    t = np.linspace(-1, 1, CAVITY_ROWS)
    S, T = np.meshgrid(s, t)
    x = S * (L.mouth_half_width + 2.0)
    y = MOUTH_Y + T * 1.0
    # the lips' depth at this x (the skin in front of the cavity)
    zs = np.minimum(skin_depth(x, MOUTH_Y + 0.35, p), skin_depth(x, MOUTH_Y - 0.35, p))
    front = zs - 0.75
    back = np.clip(1 - np.abs(T) / 0.4, 0, 1) ** 2
    z = front - 2.2 * back * (1 - S**4) - 0.5 * np.abs(S) ** 3  # a bag: closed at the sides
    pts = np.stack([x, y, z], -1).reshape(-1, 3)
    W = CAVITY_COLUMNS
    i, j = np.meshgrid(np.arange(CAVITY_ROWS - 1), np.arange(W - 1), indexing="ij")
    a = (i * W + j).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + W + 1], 1), np.stack([a, a + W + 1, a + W], 1)])
    return pts, faces.astype(np.int32), np.stack([S.ravel(), T.ravel()], 1)


@functools.lru_cache(maxsize=1)
def _template_regions() -> dict[str, np.ndarray]:
    """The named regions, from the neutral face's rest coordinates (the same for every speaker)."""
    p = FaceParams()
    _, _, slits, info = _skin(p)
    _, _, cavity_st = _cavity(p)
    n_eye = 1 + EYE_RINGS * EYE_SEGMENTS
    return _regions(info, slits, GRID_ROWS * GRID_COLUMNS, n_eye, cavity_st, p)


def _regions(info: dict, slits: dict, n_skin: int, n_eye: int, cavity_st: np.ndarray,
             p: FaceParams) -> dict[str, np.ndarray]:
    """Named vertex sets, from the rest coordinates of the skin (cm)."""
    L = LAYOUT
    W = GRID_COLUMNS
    x, y, v = info["x"], info["y"], info["v"]
    ax = np.abs(x)
    idx = np.arange(n_skin)
    out: dict[str, np.ndarray] = {}
    up, lo = lip_borders(x, p)
    i_m = ROWS_BELOW_MOUTH - 1
    i_e = ROWS_BELOW_MOUTH + ROWS_BETWEEN_SLITS - 1
    mc = slits["mouth"]
    out["mouth_upper_margin"] = (i_m + 1) * W + mc
    out["mouth_lower_margin"] = i_m * W + mc
    lips = (ax < L.mouth_half_width + 0.45) & (y < MOUTH_Y + up + 0.35) & (y > MOUTH_Y - lo - 0.35)
    out["lips"] = idx[lips]
    # the jaw: below the mouth, and below a line from the mouth corners towards the jaw hinge
    line = MOUTH_Y + np.maximum(ax - L.mouth_half_width, 0) * 0.75
    jaw_skin = idx[(v < line) & (v < -1.5)]
    ec = slits["eyes"]
    for name, sign in (("left", 1), ("right", -1)):
        cols = ec[np.sign(info["x"][i_e * W + ec]) == sign]
        out[f"{name}_upper_lid_margin"] = (i_e + 1) * W + cols
        out[f"{name}_lower_lid_margin"] = i_e * W + cols
    s, o_up, o_lo = eye_shape(ax, p)
    near = np.abs(s) < 1.25
    lid_up = near & (v > EYE_Y) & (y < EYE_Y + o_up + 1.05 * np.sqrt(np.clip(1 - (s / 1.25) ** 2, 0, 1)))
    lid_lo = near & (v < EYE_Y) & (y > EYE_Y - o_lo - 0.8 * np.sqrt(np.clip(1 - (s / 1.25) ** 2, 0, 1)))
    out["upper_lids"] = idx[lid_up]
    out["lower_lids"] = idx[lid_lo]
    brow_y = 2.85 + 0.5 * (np.exp(-(((x - 3.0) / 2.4) ** 2)) + np.exp(-(((x + 3.0) / 2.4) ** 2)))
    brows = (ax < 5.4) & (np.abs(y - brow_y) < 0.55)  # both brows and the glabella between them
    out["brows"] = idx[brows]
    out["forehead"] = idx[(y > brow_y + 0.55) & (ax < 6.0)]
    out["upper_face"] = idx[(y > EYE_Y - 1.3) & (np.abs(info["phi"]) < 1.2)]
    out["cheeks"] = idx[((ax - 3.6) ** 2 / 1.8**2 + (y + 1.8) ** 2 / 1.6**2) < 1]
    out["nose"] = idx[(ax < 2.0) & (y > -4.1) & (y < 1.9) & (ax < 0.9 + 0.4 * (1.9 - y))]
    # the jaw hinge: the left and right border columns at the hinge height
    row = int(np.argmin(np.abs(_material_rows() - (-1.5))))
    out["jaw_hinge"] = np.array([row * W + W - 1, row * W], np.int64)
    e0 = n_skin
    out["left_eyeball"] = np.arange(e0, e0 + n_eye)
    out["right_eyeball"] = np.arange(e0 + n_eye, e0 + 2 * n_eye)
    c0 = e0 + 2 * n_eye
    cav = np.arange(c0, c0 + len(cavity_st))
    out["mouth_cavity"] = cav
    out["jaw"] = np.concatenate([jaw_skin, cav[cavity_st[:, 1] < 0]])
    return {k: np.asarray(val, np.int64) for k, val in out.items()}


def make_face(params: FaceParams | None = None) -> Mesh:
    """The procedural neutral face (23,370 vertices, BIWI-normalised) with its named regions."""
    p = params or FaceParams()
    skin, skin_faces, _, _ = _skin(p)
    eyes, eye_faces = _eyeballs(p)
    cav, cav_faces, _ = _cavity(p)
    n_skin = len(skin)
    pts = np.concatenate([skin, eyes, cav])
    faces = np.concatenate([skin_faces, eye_faces + n_skin, cav_faces + n_skin + len(eyes)])
    if len(pts) != NUM_VERTICES:
        raise AssertionError(f"face has {len(pts)} vertices, expected {NUM_VERTICES}")
    pts = speaker_warp(pts, p)
    pts = unit_area(pts, faces)
    regions = {name: idx.copy() for name, idx in _template_regions().items()}
    return Mesh(pts.astype(np.float32), faces.astype(np.int32), regions)


# ------------------------------------------------------------------------------------------- speakers
def speaker_face(speaker_index: int) -> Mesh:
    """The neutral face of speaker `speaker_index`: same topology and regions, its own shape."""
    return make_face(speaker_params(speaker_index))
