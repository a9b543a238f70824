"""The procedural face's shape in centimetres: its parameters, landmarks and anatomical depth features.

facegen.face.procedural builds the mesh (grid, slits, eyeballs, mouth cavity, regions) from what is here:
the midline profile and the head's cross-section (`profile`, `cross_section`), the depth the anatomy adds
(`features`: nose, brows, cheeks, lips, chin, ...), the lids draped over the eyeballs (`drape`, `eye_shape`,
`lid_crease`) and one speaker's reshaping of the whole face (`speaker_params`, `speaker_warp`).
Y up, looking +Z, x = 0 on the midline; "left" is the subject's left (+X).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace

import numpy as np

from facegen.errors import FacegenError

# material (rest) landmarks, cm
MOUTH_Y, EYE_Y = -6.0, 1.0  # the mouth slit and the eye slits lie between two rows at these heights
PHI_MAX = 1.35  # half the angle the columns wrap around the head (rad)


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


# ------------------------------------------------------------------------------------ head and profile
def profile(v: np.ndarray, p: FaceParams) -> tuple[np.ndarray, np.ndarray]:
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


def cross_section(phi: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x and depth of the head's cross-section (a superellipse wrap) at angle phi and arc length v."""
    half_width = _pchip([-12.6, -11.0, -10.0, -9.0, -7.5, -5.0, -2.0, 1.0, 4.0, 7.0, 10.0],
                        [3.7, 3.8, 4.1, 4.8, 5.8, 6.8, 7.5, 7.9, 7.8, 7.4, 6.8], v)
    depth = _pchip([-12.6, -10.0, -9.0, -7.0, -5.0, 0.0, 5.0, 10.0],
                   [4.0, 4.2, 4.8, 6.0, 7.0, 8.3, 8.3, 7.8], v)
    n = 2.3  # a superellipse: flatter in front than an ellipse
    x = half_width * np.sin(phi)
    z = depth * ((1 - np.abs(np.sin(phi)) ** n) ** (1 / n) - 1.0)
    return x, z


def skin_depth(x: np.ndarray, v: float, p: FaceParams) -> np.ndarray:
    """Depth of the (unwarped) skin at |x| on the row at arc length v (for placing inner parts)."""
    phi = np.linspace(0.0, PHI_MAX, 2001)
    xs, zs = cross_section(phi, np.full_like(phi, v))
    y, zb = profile(np.array([v]), p)
    ax = np.abs(np.asarray(x, float))
    return np.interp(ax, xs, zs) + zb[0] + features(ax, np.full_like(ax, y[0]), p)


# ------------------------------------------------------------------------------------------- features
def lip_borders(x: np.ndarray, p: FaceParams) -> tuple[np.ndarray, np.ndarray]:
    """Heights of the upper and lower vermilion borders above/below the slit (cm, >= 0)."""
    L = LAYOUT
    s2 = np.clip((x / L.mouth_half_width) ** 2, 0, 1)
    bow = 0.06 * (np.exp(-(((x - 0.5) / 0.3) ** 2)) + np.exp(-(((x + 0.5) / 0.3) ** 2)))
    upper = p.lip_thickness * (0.95 * (1 - s2) ** 0.55 - 0.12 * np.exp(-((x / 0.28) ** 2)) + bow)
    lower = p.lip_thickness * 1.0 * (1 - s2) ** 0.65
    return np.maximum(upper, 0.0), lower


def features(x: np.ndarray, y: np.ndarray, p: FaceParams) -> np.ndarray:
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
    up, lo = lip_borders(x, p)
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


def _segment_distance(x: np.ndarray, y: np.ndarray, a: tuple[float, float],
                      b: tuple[float, float]) -> np.ndarray:
    """Distance of the points (x, y) from the segment a-b (cm)."""
    ab = np.array(b) - np.array(a)
    t = np.clip(((x - a[0]) * ab[0] + (y - a[1]) * ab[1]) / (ab @ ab), 0, 1)
    return np.hypot(x - a[0] - t * ab[0], y - a[1] - t * ab[1])


def eye_shape(ax: np.ndarray, p: FaceParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Across-eye coordinate s (-1 inner corner, +1 outer) and the rest openings of the lids (cm)."""
    L = LAYOUT
    s = (ax - L.eye_x) / L.eye_half_width
    inside = np.clip(1 - (s / 0.93) ** 2, 0, 1)  # the corners close on the slit's last columns
    upper = p.eye_opening * L.upper_open * inside**0.6 * (1 - 0.2 * s)
    lower = p.eye_opening * L.lower_open * inside**0.7 * (1 + 0.15 * s)
    return s, upper, lower


def eyeball_centre_z(p: FaceParams) -> float:
    """Depth of the eyeball centre: the cornea sits a little behind the socket's rest surface."""
    L = LAYOUT
    surface = skin_depth(np.array([L.eye_x]), EYE_Y, p)
    return float(surface[0]) - L.eyeball_b - L.lid_thickness + 0.25 - p.eye_depth


def drape(x: np.ndarray, y: np.ndarray, z: np.ndarray, p: FaceParams) -> np.ndarray:
    """Lay the lid skin over the eyeballs: a smooth maximum of the socket and an ellipsoid shell
    (eyeball + lid thickness) around each eye; a groove along the fissure lets the shell show."""
    L = LAYOUT
    zc = eyeball_centre_z(p)
    a, b = L.eyeball_a + L.lid_thickness, L.eyeball_b + L.lid_thickness
    dx, dy = np.abs(x) - L.eye_x, y - EYE_Y
    rest = z - 0.6 * np.exp(-((dx / 1.5) ** 4) - (dy / 0.9) ** 2)
    rho2 = (dx / a) ** 2 + (dy / b) ** 2
    rho = np.sqrt(rho2)
    shell = np.where(rho < 1, zc + b * np.sqrt(np.clip(1 - rho2, 0, 1)), zc - 10.0 * (rho - 1))
    k = 0.35
    return 0.5 * (rest + shell + np.sqrt((rest - shell) ** 2 + k * k))


def fade_sides(phi: np.ndarray) -> np.ndarray:
    return 1 - _smoothstep((np.abs(phi) - 0.95) / 0.35)


def lid_crease(x: np.ndarray, y: np.ndarray, p: FaceParams) -> np.ndarray:
    s, up, _ = eye_shape(np.abs(x), p)
    above = y - (EYE_Y + up)
    return -0.09 * np.exp(-(((above - 0.62) / 0.16) ** 2)) * np.clip(1 - s**2, 0, 1) ** 0.5


def speaker_warp(pts: np.ndarray, p: FaceParams) -> np.ndarray:
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
