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
"Left" is the subject's left (+X).
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.errors import FacegenError
from facegen.mesh import Mesh, read_mesh, read_region, unit_area, write_mesh, write_region

NUM_VERTICES = 23370
GRID_COLUMNS, GRID_ROWS = 123, 176  # skin grid
ROWS_BELOW_MOUTH, ROWS_BETWEEN_SLITS = 52, 64  # the rest (60) lie above the eye slit
EYE_RINGS, EYE_SEGMENTS = 13, 40  # eyeball cap: a pole and 13 rings of 40
CAVITY_COLUMNS, CAVITY_ROWS = 40, 17  # mouth cavity grid

# material (rest) landmarks, cm
MOUTH_Y, EYE_Y = -6.0, 1.0  # the mouth slit and the eye slits lie between two rows at these heights
BOTTOM_V, TOP_V = -12.6, 10.0  # arc-length extent of the rows
PHI_MAX = 1.35  # half the angle the columns wrap around the head (rad)

TEMPLATES = Path(__file__).resolve().parents[2] / "templates"  # the committed neutral face (source tree)
# files written by write_templates (community names for the lips and upper-face regions)
REGION_FILES = {"lve.txt": "lips", "fdd.txt": "upper_face"}


@dataclass(frozen=True)
class FaceParams:
    """Shape of one face (cm and multipliers); the defaults are the neutral template."""

    face_width: float = 1.0  # x scale
    face_height: float = 1.0  # y scale
    jaw_width: float = 1.0  # x scale of the lower face sides
    chin_length: float = 0.0  # cm, chin moves down
    chin_prominence: float = 1.0
    nose_length: float = 0.0  # cm, nose tip moves down
    nose_protrusion: float = 1.0
    nose_width: float = 1.0
    mouth_width: float = 1.0
    lip_thickness: float = 1.0  # vermilion height and fullness
    brow_height: float = 0.0  # cm, brows and forehead move up
    brow_prominence: float = 1.0
    eye_spacing: float = 1.0
    eye_opening: float = 1.0
    eye_depth: float = 0.0  # cm, eyes set deeper (+) or more prominent (-)
    cheek_fullness: float = 1.0
    forehead_slope: float = 1.0


@dataclass(frozen=True)
class _Layout:
    """Fixed landmarks of the canonical face (cm)."""

    eye_x: float = 3.15  # eye centre (slit centre) |x|
    eye_half_width: float = 1.42
    eyeball_a: float = 1.6  # ellipsoid semi-axes: a along x, b along y and z
    eyeball_b: float = 1.2
    lid_thickness: float = 0.13
    mouth_half_width: float = 2.45
    upper_open: float = 0.52  # rest opening of the upper / lower lid (cm)
    lower_open: float = 0.3
    mouth_open: float = 0.05  # rest gap of each lip at the centre (cm)


LAYOUT = _Layout()


# ----------------------------------------------------------------------------------------------- helpers
def _smoothstep(t: np.ndarray | float) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _gauss(x: np.ndarray, y: np.ndarray, cx: float, cy: float, sx: float, sy: float) -> np.ndarray:
    return np.exp(-(((x - cx) / sx) ** 2) - ((y - cy) / sy) ** 2)


def _window(t: np.ndarray, lo: float, hi: float, ramp: float) -> np.ndarray:
    """1 inside [lo, hi], smooth ramps of width `ramp` outside, 0 beyond."""
    return _smoothstep((t - lo + ramp) / ramp) * _smoothstep((hi + ramp - t) / ramp)


def _pair(x: np.ndarray, y: np.ndarray, cx: float, cy: float, sx: float, sy: float) -> np.ndarray:
    """A bilateral feature: Gaussians at (+cx, cy) and (-cx, cy) (smooth across the midline)."""
    return _gauss(x, y, cx, cy, sx, sy) + _gauss(x, y, -cx, cy, sx, sy)


def _pchip(xs: list[float], ys: list[float], x: np.ndarray) -> np.ndarray:
    from scipy.interpolate import PchipInterpolator

    order = np.argsort(xs)
    return PchipInterpolator(np.asarray(xs, float)[order], np.asarray(ys, float)[order])(x)


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


def _profile(v: np.ndarray, p: FaceParams) -> tuple[np.ndarray, np.ndarray]:
    """Height y and base depth z of the midline at arc length v: forehead and under-chin curve back."""
    y = v.copy()
    z = np.zeros_like(v)
    top, r_top = 4.5, 10.0 / p.forehead_slope
    m = v > top
    th = (v[m] - top) / r_top
    y[m] = top + r_top * np.sin(th)
    z[m] = -r_top * (1 - np.cos(th))
    chin, r_chin = -9.9, 1.5
    m = v < chin
    th = (chin - v[m]) / r_chin
    arc = np.minimum(th, np.pi / 2)
    y[m] = chin - r_chin * np.sin(arc)
    z[m] = -r_chin * (1 - np.cos(arc)) - r_chin * np.maximum(th - np.pi / 2, 0)  # then straight back
    return y, z


def _cross_section(phi: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x and depth of the head's cross-section (a superellipse wrap) at angle phi and arc length v."""
    half_width = _pchip([-12.6, -11.0, -10.0, -9.0, -7.5, -5.0, -2.0, 1.0, 4.0, 7.0, 10.0],
                        [3.7, 3.8, 4.1, 4.8, 5.8, 6.8, 7.5, 7.9, 7.8, 7.4, 6.8], v)
    depth = _pchip([-12.6, -10.0, -9.0, -7.0, -5.0, 0.0, 5.0, 10.0], [4.0, 4.2, 4.8, 6.0, 7.0, 8.3, 8.3, 7.8], v)
    n = 2.3  # a superellipse: flatter in front than an ellipse
    x = half_width * np.sin(phi)
    z = depth * ((1 - np.abs(np.sin(phi)) ** n) ** (1 / n) - 1.0)
    return x, z


def _skin_depth(x: np.ndarray, v: float, p: FaceParams) -> np.ndarray:
    """Depth of the (unwarped) skin at |x| on the row at arc length v (for placing inner parts)."""
    phi = np.linspace(0.0, PHI_MAX, 2001)
    xs, zs = _cross_section(phi, np.full_like(phi, v))
    y, zb = _profile(np.array([v]), p)
    ax = np.abs(np.asarray(x, float))
    return np.interp(ax, xs, zs) + zb[0] + _features(ax, np.full_like(ax, y[0]), p)


# ------------------------------------------------------------------------------------------- features
def _lip_borders(x: np.ndarray, p: FaceParams) -> tuple[np.ndarray, np.ndarray]:
    """Heights of the upper and lower vermilion borders above/below the slit (cm, >= 0)."""
    L = LAYOUT
    s2 = np.clip((x / L.mouth_half_width) ** 2, 0, 1)
    bow = 0.06 * (np.exp(-(((x - 0.5) / 0.3) ** 2)) + np.exp(-(((x + 0.5) / 0.3) ** 2)))
    upper = p.lip_thickness * (0.95 * (1 - s2) ** 0.55 - 0.12 * np.exp(-((x / 0.28) ** 2)) + bow)
    lower = p.lip_thickness * 1.0 * (1 - s2) ** 0.65
    return np.maximum(upper, 0.0), lower


def _features(x: np.ndarray, y: np.ndarray, p: FaceParams) -> np.ndarray:
    """Depth added to the base wrap by the face's anatomy, at (x, y) in cm (even in x)."""
    L = LAYOUT
    ax = np.abs(x)  # only where the function of it is flat at 0
    z = np.zeros_like(x)
    # forehead: a broad dome, temples
    z += 0.25 * _gauss(x, y, 0.0, 6.0, 4.0, 2.6)
    z -= 0.45 * _pair(x, y, 6.4, 3.0, 1.2, 2.2)
    # brow ridge along an arc over each eye
    brow_y = 2.85 + 0.5 * (np.exp(-(((x - 3.0) / 2.4) ** 2)) + np.exp(-(((x + 3.0) / 2.4) ** 2)))
    z += p.brow_prominence * 0.5 * np.exp(-(((y - brow_y) / 0.75) ** 2)) * _window(ax, 0.0, 4.8, 1.2)
    # nasion and the eye sockets
    z -= 0.3 * _gauss(x, y, 0.0, 1.75, 0.9, 0.7)
    z -= 1.0 * _pair(x, y, L.eye_x, EYE_Y + 0.25, 1.9, 1.35)
    z -= 0.2 * _pair(x, y, 2.5, -0.5, 0.9, 0.5)  # tear troughs
    # cheeks and cheekbones
    z += p.cheek_fullness * 0.55 * _pair(x, y, 3.5, -1.8, 1.7, 1.7)
    z += 0.35 * _pair(x, y, 5.0, 0.2, 1.4, 1.2)
    # nose: a dorsum of varying height and width, and the alae
    yc = np.clip(y, -4.2, 2.4)
    h = _pchip([2.4, 1.6, 0.5, -1.0, -1.9, -2.45, -2.95, -3.45, -3.85, -4.2],
               [0.0, 0.25, 0.85, 1.6, 2.15, 2.4, 2.15, 1.35, 0.5, 0.0], yc)
    w = p.nose_width * _pchip([2.4, 1.0, -1.0, -2.2, -3.0, -4.2], [0.95, 0.62, 0.7, 0.9, 1.0, 0.9], yc)
    on = (y > -4.2) & (y < 2.4)
    z += np.where(on, p.nose_protrusion * h * np.exp(-((x / w) ** 2) - 0.35 * (x / w) ** 4), 0.0)
    z += p.nose_protrusion * 0.8 * _pair(x, y, 1.2 * p.nose_width, -3.15, 0.5, 0.45)
    z -= 0.12 * _pair(x, y, 1.75 * p.nose_width, -3.0, 0.25, 0.6)  # alar grooves
    # the muzzle (dental arch) carrying the lips
    z += 1.0 * np.exp(-((x / 2.9) ** 2)) * _window(y, -7.6, -4.3, 2.2)
    # upper lip: philtrum, vermilion; lower lip; the roll-in at the slit
    z -= 0.08 * _gauss(x, y, 0.0, -4.6, 0.22, 0.5)
    z += 0.06 * _pair(x, y, 0.45, -4.6, 0.18, 0.5)
    up, lo = _lip_borders(x, p)
    lat = _window(ax, -1.0, L.mouth_half_width - 0.35, 0.6)
    t = (y - MOUTH_Y) / np.maximum(up, 0.15)
    z += p.lip_thickness * 0.42 * lat * np.exp(-(((t - 0.7) / 0.45) ** 2)) * (y > MOUTH_Y - 0.1)
    t = (MOUTH_Y - y) / np.maximum(lo, 0.15)
    z += p.lip_thickness * 0.5 * lat * np.exp(-(((t - 0.5) / 0.45) ** 2)) * (y < MOUTH_Y + 0.1)
    z -= 0.32 * np.exp(-(((y - MOUTH_Y) / 0.14) ** 2)) * _window(ax, -1, L.mouth_half_width, 0.4)
    z -= 0.18 * _pair(x, y, L.mouth_half_width + 0.2, MOUTH_Y - 0.05, 0.35, 0.35)  # corners
    # nasolabial folds: a crease from the ala to beside the mouth corner
    d = _segment_distance(ax, y, (1.85, -3.4), (2.95, -6.4))
    z -= 0.08 * np.exp(-((d / 0.4) ** 2))
    # mentolabial sulcus and the chin
    z -= 0.3 * _gauss(x, y, 0.0, -7.85, 2.0, 0.55)
    z += p.chin_prominence * 0.7 * _gauss(x, y, 0.0, -9.5, 1.7, 1.0)
    return z


def _segment_distance(x: np.ndarray, y: np.ndarray, a: tuple[float, float], b: tuple[float, float]) -> np.ndarray:
    ab = np.array(b) - np.array(a)
    t = np.clip(((x - a[0]) * ab[0] + (y - a[1]) * ab[1]) / (ab @ ab), 0, 1)
    return np.hypot(x - a[0] - t * ab[0], y - a[1] - t * ab[1])


def _eye_shape(ax: np.ndarray, p: FaceParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Across-eye coordinate s (-1 inner corner, +1 outer) and the rest openings of the lids (cm)."""
    L = LAYOUT
    s = (ax - L.eye_x) / L.eye_half_width
    inside = np.clip(1 - (s / 0.93) ** 2, 0, 1)  # the corners close on the slit's last columns
    upper = p.eye_opening * L.upper_open * inside**0.6 * (1 - 0.2 * s)
    lower = p.eye_opening * L.lower_open * inside**0.7 * (1 + 0.15 * s)
    return s, upper, lower


def _eyeball_centre_z(p: FaceParams) -> float:
    """Depth of the eyeball centre: the cornea sits a little behind the socket's rest surface."""
    L = LAYOUT
    surface = _skin_depth(np.array([L.eye_x]), EYE_Y, p)
    return float(surface[0]) - L.eyeball_b - L.lid_thickness + 0.25 - p.eye_depth


def _drape(x: np.ndarray, y: np.ndarray, z: np.ndarray, p: FaceParams) -> np.ndarray:
    """Lay the lid skin over the eyeballs: a smooth maximum of the socket and an ellipsoid shell
    (eyeball + lid thickness) around each eye; a groove along the fissure lets the shell show."""
    L = LAYOUT
    zc = _eyeball_centre_z(p)
    a, b = L.eyeball_a + L.lid_thickness, L.eyeball_b + L.lid_thickness
    dx, dy = np.abs(x) - L.eye_x, y - EYE_Y
    rest = z - 0.6 * np.exp(-((dx / 1.5) ** 4) - (dy / 0.9) ** 2)
    rho2 = (dx / a) ** 2 + (dy / b) ** 2
    rho = np.sqrt(rho2)
    shell = np.where(rho < 1, zc + b * np.sqrt(np.clip(1 - rho2, 0, 1)), zc - 10.0 * (rho - 1))
    k = 0.35
    return 0.5 * (rest + shell + np.sqrt((rest - shell) ** 2 + k * k))


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
            s, _, _ = _eye_shape(axr, p)
            in_slit = np.abs(s) < 1.0
            _, up, low = _eye_shape(ax, p)
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
    y, zb = _profile(v, p)
    x, zc = _cross_section(phi, v)
    dy, slits = _slit_warp(x, v, cols, p)
    y = y + dy
    z = zb + zc + _features(x, y, p) * _fade_sides(phi)
    z = _drape(x, y, z, p)
    z += _lid_crease(x, y, p)
    pts = np.stack([x, y, z], -1).reshape(-1, 3)
    info = {"v": v.reshape(-1), "x": x.reshape(-1), "y": y.reshape(-1), "phi": phi.reshape(-1)}
    return pts, _grid_faces(slits), slits, info


def _fade_sides(phi: np.ndarray) -> np.ndarray:
    return 1 - _smoothstep((np.abs(phi) - 0.95) / 0.35)


def _lid_crease(x: np.ndarray, y: np.ndarray, p: FaceParams) -> np.ndarray:
    s, up, _ = _eye_shape(np.abs(x), p)
    above = y - (EYE_Y + up)
    return -0.09 * np.exp(-(((above - 0.62) / 0.16) ** 2)) * np.clip(1 - s**2, 0, 1) ** 0.5


def _eyeballs(p: FaceParams) -> tuple[np.ndarray, np.ndarray]:
    L = LAYOUT
    tp, faces = _cap(EYE_RINGS, EYE_SEGMENTS, np.radians(88))
    th, ps = tp[:, 0], tp[:, 1]
    unit = np.stack([L.eyeball_a * np.sin(th) * np.cos(ps), L.eyeball_b * np.sin(th) * np.sin(ps),
                     L.eyeball_b * np.cos(th)], 1)
    zc = _eyeball_centre_z(p)
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
    zs = np.minimum(_skin_depth(x, MOUTH_Y + 0.35, p), _skin_depth(x, MOUTH_Y - 0.35, p))
    front = zs - 0.75
    back = np.clip(1 - np.abs(T) / 0.4, 0, 1) ** 2
    z = front - 2.2 * back * (1 - S**4) - 0.5 * np.abs(S) ** 3  # a bag: closed at the sides
    pts = np.stack([x, y, z], -1).reshape(-1, 3)
    W = CAVITY_COLUMNS
    i, j = np.meshgrid(np.arange(CAVITY_ROWS - 1), np.arange(W - 1), indexing="ij")
    a = (i * W + j).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + W + 1], 1), np.stack([a, a + W + 1, a + W], 1)])
    return pts, faces.astype(np.int32), np.stack([S.ravel(), T.ravel()], 1)


def _speaker_warp(pts: np.ndarray, p: FaceParams) -> np.ndarray:
    """Smooth reshaping of the whole face (skin, eyes, cavity) for one speaker."""
    L = LAYOUT
    x, y, z = pts[:, 0].copy(), pts[:, 1].copy(), pts[:, 2].copy()
    ax = np.abs(x)
    # eye spacing: shift the eye region sideways
    x += (p.eye_spacing - 1) * x * np.exp(-(((ax - L.eye_x) / 2.6) ** 2) - ((y - EYE_Y) / 2.5) ** 2)
    # brows and forehead up
    y += p.brow_height * _smoothstep((y - (EYE_Y + 0.9)) / 1.8)
    # nose length: the nose tip region down
    y -= p.nose_length * np.exp(-((x / 1.9) ** 2)) * _window(y, -3.3, -1.8, 1.6)
    # mouth width
    x += (p.mouth_width - 1) * x * np.exp(-((x / 3.6) ** 4)) * _window(y, -7.2, -4.8, 1.5)
    # jaw width and chin length
    lower = _smoothstep((-3.5 - y) / 3.5)
    x += (p.jaw_width - 1) * x * _smoothstep((ax - 2.0) / 3.0) * lower
    y -= p.chin_length * _smoothstep((-7.0 - y) / 2.5)
    # global proportions
    x *= p.face_width
    y = EYE_Y + (y - EYE_Y) * p.face_height
    return np.stack([x, y, z], 1)


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
    up, lo = _lip_borders(x, p)
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
    s, o_up, o_lo = _eye_shape(ax, p)
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
    pts = _speaker_warp(pts, p)
    pts = unit_area(pts, faces)
    regions = {name: idx.copy() for name, idx in _template_regions().items()}
    return Mesh(pts.astype(np.float32), faces.astype(np.int32), regions)


# ------------------------------------------------------------------------------------------- speakers
_RANGES = {  # per-speaker variation: (low, high) for each shape parameter
    "face_width": (0.93, 1.07), "face_height": (0.94, 1.06), "jaw_width": (0.9, 1.1),
    "chin_length": (-0.4, 0.5), "chin_prominence": (0.7, 1.3), "nose_length": (-0.3, 0.45),
    "nose_protrusion": (0.82, 1.18), "nose_width": (0.85, 1.2), "mouth_width": (0.9, 1.1),
    "lip_thickness": (0.75, 1.25), "brow_height": (-0.25, 0.35), "brow_prominence": (0.6, 1.4),
    "eye_spacing": (0.94, 1.06), "eye_opening": (0.85, 1.15), "eye_depth": (-0.15, 0.2),
    "cheek_fullness": (0.6, 1.5), "forehead_slope": (0.8, 1.25),
}


def speaker_params(speaker_index: int) -> FaceParams:
    """Shape parameters of speaker `speaker_index` (deterministic; any index >= 0)."""
    if speaker_index < 0:
        raise FacegenError(f"speaker index {speaker_index} is negative: use 0 or more")
    digest = hashlib.sha256(f"facegen-speaker-{speaker_index}".encode()).digest()
    u = np.frombuffer(digest, dtype=np.uint8)[: len(_RANGES)] / 255.0
    values = {name: lo + (hi - lo) * float(k) for (name, (lo, hi)), k in zip(_RANGES.items(), u)}
    return replace(FaceParams(), **values)


def speaker_face(speaker_index: int) -> Mesh:
    """The neutral face of speaker `speaker_index`: same topology and regions, its own shape."""
    return make_face(speaker_params(speaker_index))


# ------------------------------------------------------------------------------------------- files
def write_templates(folder: str | os.PathLike) -> list[Path]:
    """Write the neutral face: face.ply, lve.txt (lips), fdd.txt (upper face) and regions/<name>.txt
    for every other region (the rig's layout). Returns the paths written."""
    folder = Path(folder)
    (folder / "regions").mkdir(parents=True, exist_ok=True)
    mesh = make_face()
    written = [folder / "face.ply"]
    with atomic_path(written[0]) as tmp:
        write_mesh(mesh, tmp)  # binary PLY: float32 vertices, int32 triangles
    targets = [(folder / f, mesh.regions[r]) for f, r in REGION_FILES.items()]
    targets += [(folder / "regions" / f"{name}.txt", idx) for name, idx in sorted(mesh.regions.items())
                if name not in REGION_FILES.values()]
    for path, idx in targets:
        with atomic_path(path) as tmp:
            write_region(idx, tmp)
        written.append(path)
    return written


def load_template(folder: str | os.PathLike = TEMPLATES) -> Mesh:
    """Read a face written by write_templates (mesh and all its regions)."""
    folder = Path(folder)
    mesh = read_mesh(folder / "face.ply")
    for name, region in REGION_FILES.items():
        mesh.regions[region] = read_region(folder / name)
    for path in sorted((folder / "regions").glob("*.txt")):
        mesh.regions[path.stem] = read_region(path)
    return mesh


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m facegen.synth.face",
                                     description="Write the procedural neutral face and its region files.")
    parser.add_argument("folder", nargs="?", default="templates")
    for path in write_templates(parser.parse_args(argv).folder):
        print(path)


if __name__ == "__main__":
    main()
