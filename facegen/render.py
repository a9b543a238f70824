"""Preview videos: offscreen shaded renders of an animation, with its audio, as H.264 MP4.

Renderer: a z-buffer software rasteriser compiled with numba (already installed with librosa), chosen
over the GPU-style options after measuring on this 2-core, GPU-less machine with the BIWI template
(46,068 triangles, one 512 x 512 view):

    numba rasteriser (this module)   ~17 ms CPU per view with 2 x 2 supersampling, on one core
                                     (z-buffer 8 ms + shading 9 ms; ~36 ms per two-view frame)
    moderngl on Mesa llvmpipe (EGL)  ~30 ms per view without anti-aliasing, ~45 ms with 4x MSAA,
                                     using both cores, plus system packages (libegl1, libgl1-mesa-dri)
    plain numpy (vectorised)         no z-buffer without a per-pixel scatter-min: far slower

A 5 s clip (125 frames x 2 views) costs ~5.5 s of CPU including H.264 encoding: ~3 s on two free cores.

The numba kernels release the GIL, so two frames render at once on two threads while ffmpeg encodes.
Nothing outside PyPI is needed: no EGL/OSMesa system libraries, no display, and the pixels are the same on
every machine (tests can reason about them). The first call on a new install compiles the kernels (a few
seconds); numba caches them beside this module (or in its user cache) for later runs.

Image: per-pixel (Phong) shading of interpolated vertex normals, a key light from the upper left and a
fill light from the right (fixed to the camera, so every view is lit alike), a neutral skin colour, a
dark background, two-sided lighting (the mask is an open surface), 2 x 2 supersampling, sRGB output.

Camera: the face is Y up and looks +Z (BIWI's normalised convention). Each view is a yaw about the
vertical axis (front 0°, three_quarter 40° towards the subject's left, profile 90°); a 20° perspective
camera is framed once per clip from the template (its extent in every view, the same distance for all
views) so that motion shows as motion.

Layout: the normal video shows the views side by side, `size` pixels square each (front + three-quarter:
1024 x 512 by default). With a comparison (`compare=B`) the video is exactly twice as wide: the left half
is A's views as in the normal video, the right half is B in the same views, painted with the per-vertex
error |A - B| (grey at 0 → yellow → orange → red at the scale's top). A title strip names A and B and a
colour bar at the bottom states the scale, in the mesh's units and in % of the face size (the template's
bounding-box diagonal).

Video: rgb24 frames piped to the ffmpeg binary of imageio-ffmpeg, H.264 yuv420p at the clip's fps, the
audio (trimmed or padded to the clip's duration) muxed in as AAC, written atomically: an error or Ctrl-C
leaves no partial file.
"""

from __future__ import annotations

import math
import os
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from collections import deque
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numba
import numpy as np

from facegen.animation import Animation, check_animation
from facegen.atomic import atomic_path, check_writable
from facegen.errors import FacegenError
from facegen.mesh import Mesh

VIEWS: dict[str, float] = {"front": 0.0, "three_quarter": 40.0, "profile": 90.0}  # yaw, degrees
DEFAULT_VIEWS = ("front", "three_quarter")
VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv")
FIELD_OF_VIEW = 20.0  # degrees, vertical and horizontal (square views)
FILL = 0.84  # the template fills this fraction of a view's width or height
SKIN = (0.86, 0.69, 0.60)  # sRGB
REGION_COLORS = {"lips": (0.72, 0.42, 0.42), "left_eyeball": (0.93, 0.93, 0.90),
                 "right_eyeball": (0.93, 0.93, 0.90), "mouth_cavity": (0.35, 0.16, 0.16)}  # sRGB


def face_colors(regions: dict[str, np.ndarray] | None, num_vertices: int) -> np.ndarray | None:
    """Per-vertex sRGB colours: skin, with lips, eyeballs and mouth cavity tinted when the mesh names them
    (facegen's procedural face does; BIWI-topology bundles name only lips and upper face)."""
    named = [(k, v) for k, v in (regions or {}).items() if k in REGION_COLORS]
    if not named:
        return None
    colors = np.tile(np.asarray(SKIN, np.float32), (num_vertices, 1))
    for name, idx in named:
        idx = np.asarray(idx)
        colors[idx[(idx >= 0) & (idx < num_vertices)]] = REGION_COLORS[name]
    return colors
BACKGROUND = (0.08, 0.09, 0.11)  # sRGB
TEXT = (0.85, 0.86, 0.88)  # sRGB
HEAT_STOPS = ((0.78, 0.80, 0.84), (0.99, 0.87, 0.33), (0.96, 0.50, 0.12), (0.78, 0.07, 0.07))  # sRGB, 0 → 1
# lights in view space (x right, y up, z towards the viewer): direction, intensity
KEY_LIGHT = ((-0.45, 0.55, 0.70), 0.85)
FILL_LIGHT = ((0.70, -0.05, 0.70), 0.30)
AMBIENT = 0.12
SPECULAR, SHININESS_DOUBLINGS = 0.12, 5  # Blinn exponent 2**5 = 32
FRAME_WINDOW = 4  # frames rendered ahead of the encoder


# ---------------------------------------------------------------------------------------------- camera


@dataclass
class Camera:
    """A pinhole camera: `rotation` rows are the view's right, up and forward axes (world space)."""

    eye: np.ndarray  # [3] camera position
    rotation: np.ndarray  # [3, 3] world → camera (rows: right, up, forward)
    focal: float  # pixels
    size: int  # square view, pixels

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates [N, 2] (x right, y down, pixel centres at +0.5) and depth [N] of world points."""
        cam = (np.asarray(points, np.float64) - self.eye) @ self.rotation.T
        depth = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = self.size / 2 + self.focal * cam[:, 0] / depth
            y = self.size / 2 - self.focal * cam[:, 1] / depth
        return np.stack([x, y], 1), depth


def _view_axes(yaw_degrees: float) -> np.ndarray:
    """Rows right, up, forward of a camera orbiting the vertical axis, looking at a face that looks +Z."""
    yaw = math.radians(yaw_degrees)
    forward = np.array([-math.sin(yaw), 0.0, -math.cos(yaw)])  # from the camera towards the face
    up = np.array([0.0, 1.0, 0.0])
    right = np.cross(forward, up)
    return np.stack([right, up, forward])


def frame_cameras(template: np.ndarray, views: Sequence[str], size: int) -> list[Camera]:
    """One camera per view, framed on the template: the same distance for every view, each view centred."""
    views = check_views(views)
    points = np.asarray(template, np.float64)
    centre = (points.min(0) + points.max(0)) / 2
    focal = size / 2 / math.tan(math.radians(FIELD_OF_VIEW) / 2)
    half = FILL * size / 2
    targets, axes, distance = [], [], 0.0
    for view in views:
        rot = _view_axes(VIEWS[view])
        local = (points - centre) @ rot.T
        mid = (local.min(0) + local.max(0)) / 2  # centre the view on the template's extent in it
        target = centre + mid[0] * rot[0] + mid[1] * rot[1]
        local = (points - target) @ rot.T
        # eye at target - d * forward: depth of a point is d + local z; fit |x|, |y| within `half` pixels
        need = focal * np.maximum(np.abs(local[:, 0]), np.abs(local[:, 1])) / half - local[:, 2]
        distance = max(distance, float(need.max()))
        targets.append(target)
        axes.append(rot)
    return [Camera(t - distance * r[2], r, focal, size) for t, r in zip(targets, axes, strict=True)]


def check_views(views: Sequence[str] | str) -> tuple[str, ...]:
    """Validate view names (a sequence or a comma-separated string)."""
    if isinstance(views, str):
        views = [v.strip() for v in views.split(",") if v.strip()]
    views = tuple(views)
    unknown = [v for v in views if v not in VIEWS]
    if not views or unknown:
        raise FacegenError(
            f"unknown view {', '.join(unknown) or '(none given)'}: choose from {', '.join(VIEWS)} "
            "(comma-separated, e.g. front,three_quarter)"
        )
    return views


# ---------------------------------------------------------------------------------------------- kernels


@numba.njit(cache=True, nogil=True, fastmath=True)
def _vertex_normals(vertices: np.ndarray, faces: np.ndarray, out: np.ndarray) -> None:
    """Area-weighted vertex normals (unit length; zero where a vertex has no area)."""
    out[:] = 0.0
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ux = vertices[b, 0] - vertices[a, 0]
        uy = vertices[b, 1] - vertices[a, 1]
        uz = vertices[b, 2] - vertices[a, 2]
        vx = vertices[c, 0] - vertices[a, 0]
        vy = vertices[c, 1] - vertices[a, 1]
        vz = vertices[c, 2] - vertices[a, 2]
        nx = uy * vz - uz * vy
        ny = uz * vx - ux * vz
        nz = ux * vy - uy * vx
        for k in (a, b, c):
            out[k, 0] += nx
            out[k, 1] += ny
            out[k, 2] += nz
    for i in range(out.shape[0]):
        n = math.sqrt(out[i, 0] ** 2 + out[i, 1] ** 2 + out[i, 2] ** 2)
        if n > 0.0:
            out[i, 0] /= n
            out[i, 1] /= n
            out[i, 2] /= n


@numba.njit(cache=True, nogil=True, fastmath=True)
def _to_view(
    vertices: np.ndarray,
    normals: np.ndarray,
    eye: np.ndarray,
    rotation: np.ndarray,
    focal: float,
    centre: float,
    xy: np.ndarray,
    inv_depth: np.ndarray,
    view_normals: np.ndarray,
) -> None:
    """Camera.project for the rasteriser (xy pixels, 1/depth or -1 behind the camera) and the normals
    in view space (x right, y up, z towards the viewer)."""
    for i in range(vertices.shape[0]):
        px = vertices[i, 0] - eye[0]
        py = vertices[i, 1] - eye[1]
        pz = vertices[i, 2] - eye[2]
        x = rotation[0, 0] * px + rotation[0, 1] * py + rotation[0, 2] * pz
        y = rotation[1, 0] * px + rotation[1, 1] * py + rotation[1, 2] * pz
        z = rotation[2, 0] * px + rotation[2, 1] * py + rotation[2, 2] * pz
        if z > 1e-6:
            inv_depth[i] = 1.0 / z
            xy[i, 0] = centre + focal * x / z
            xy[i, 1] = centre - focal * y / z
        else:
            inv_depth[i] = -1.0
            xy[i, 0] = 0.0
            xy[i, 1] = 0.0
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        view_normals[i, 0] = rotation[0, 0] * nx + rotation[0, 1] * ny + rotation[0, 2] * nz
        view_normals[i, 1] = rotation[1, 0] * nx + rotation[1, 1] * ny + rotation[1, 2] * nz
        view_normals[i, 2] = -(rotation[2, 0] * nx + rotation[2, 1] * ny + rotation[2, 2] * nz)


SUBPIXEL = 256  # vertex positions snap to 1/256 pixel: exact integer edge functions


@numba.njit(cache=True, nogil=True, fastmath=True)
def _rasterize(
    xy: np.ndarray,
    inv_depth: np.ndarray,
    faces: np.ndarray,
    tri: np.ndarray,
    bary: np.ndarray,
    zbuf: np.ndarray,
) -> None:
    """Z-buffer the triangles: per pixel, the nearest triangle and its perspective-correct barycentrics.

    xy: [V, 2] pixel coordinates, inv_depth: [V] 1/depth (<= 0 behind the camera), tri: [H, W] out
    (-1 = background), bary: [H, W, 2] out (weights of the first two corners), zbuf: [H, W] scratch.
    Edge functions are evaluated in integers on positions snapped to 1/SUBPIXEL pixel, so two triangles
    that share an edge never both miss a pixel centre on it (no cracks), as on a GPU.
    """
    height, width = tri.shape
    zbuf[:] = 0.0
    tri[:] = -1
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        za, zb, zc = inv_depth[a], inv_depth[b], inv_depth[c]
        if not (za > 0.0 and zb > 0.0 and zc > 0.0):  # behind the camera, or NaN
            continue
        x0, y0, x1, y1, x2, y2 = xy[a, 0], xy[a, 1], xy[b, 0], xy[b, 1], xy[c, 0], xy[c, 1]
        lo_x, hi_x = min(x0, x1, x2) - 0.5, max(x0, x1, x2) - 0.5
        lo_y, hi_y = min(y0, y1, y2) - 0.5, max(y0, y1, y2) - 0.5
        if not (hi_x >= 0.0 and lo_x <= width - 1 and hi_y >= 0.0 and lo_y <= height - 1):
            continue  # off screen (or NaN)
        X0, Y0 = np.int64(math.floor(x0 * SUBPIXEL + 0.5)), np.int64(math.floor(y0 * SUBPIXEL + 0.5))
        X1, Y1 = np.int64(math.floor(x1 * SUBPIXEL + 0.5)), np.int64(math.floor(y1 * SUBPIXEL + 0.5))
        X2, Y2 = np.int64(math.floor(x2 * SUBPIXEL + 0.5)), np.int64(math.floor(y2 * SUBPIXEL + 0.5))
        area = (X1 - X0) * (Y2 - Y0) - (X2 - X0) * (Y1 - Y0)
        if area == 0:
            continue
        sign = np.int64(1) if area > 0 else np.int64(-1)
        inv_area = 1.0 / (area * sign)
        xmin, xmax = max(math.ceil(lo_x), 0), min(math.floor(hi_x), width - 1)
        ymin, ymax = max(math.ceil(lo_y), 0), min(math.floor(hi_y), height - 1)
        # edge function of corner k at pixel centre (cx, cy), times sign: >= 0 on the triangle's side
        step0, step1, step2 = (
            (Y1 - Y2) * SUBPIXEL * sign,
            (Y2 - Y0) * SUBPIXEL * sign,
            (Y0 - Y1) * SUBPIXEL * sign,
        )
        cx = xmin * SUBPIXEL + SUBPIXEL // 2
        da, db = za - zc, zb - zc
        for py in range(ymin, ymax + 1):
            cy = py * SUBPIXEL + SUBPIXEL // 2
            e0 = ((X1 - cx) * (Y2 - cy) - (X2 - cx) * (Y1 - cy)) * sign
            e1 = ((X2 - cx) * (Y0 - cy) - (X0 - cx) * (Y2 - cy)) * sign
            e2 = ((X0 - cx) * (Y1 - cy) - (X1 - cx) * (Y0 - cy)) * sign
            for px in range(xmin, xmax + 1):
                if e0 >= 0 and e1 >= 0 and e2 >= 0:
                    w0, w1 = e0 * inv_area, e1 * inv_area
                    iz = zc + w0 * da + w1 * db  # 1/depth is linear in screen space
                    if iz > zbuf[py, px]:
                        zbuf[py, px] = iz
                        tri[py, px] = f
                        bary[py, px, 0] = w0 * za / iz  # perspective-correct
                        bary[py, px, 1] = w1 * zb / iz
                e0 += step0
                e1 += step1
                e2 += step2


@numba.njit(cache=True, nogil=True, fastmath=True)
def _shade(
    tri: np.ndarray,
    bary: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    colors: np.ndarray,
    lights: np.ndarray,
    background: np.ndarray,
    srgb: np.ndarray,
    ss: int,
    out: np.ndarray,
) -> None:
    """Shade each output pixel from its ss x ss samples and write sRGB uint8.

    The samples' interpolated normals and colours are averaged (normals flipped towards the camera:
    two-sided lighting), the pixel is lit once with the averaged normal (Phong: per pixel, not per
    vertex), and blended with the background by the fraction of samples the surface covers.
    normals: [V, 3] in view space (x right, y up, z towards the viewer); colors: [V, 3] linear RGB;
    lights: rows key direction, fill direction (unit, view space), then [key, fill, ambient, specular,
    log2 of the shininess, 0]; background: [3] linear RGB; srgb: [N] uint8 table of linear 0..1 → sRGB.
    """
    height, width = out.shape[0], out.shape[1]
    kx, ky, kz = lights[0, 0], lights[0, 1], lights[0, 2]
    fx, fy, fz = lights[1, 0], lights[1, 1], lights[1, 2]
    key, fill, ambient, spec = lights[2, 0], lights[2, 1], lights[2, 2], lights[2, 3]
    doublings = int(lights[2, 4])
    # Blinn half vector of the key light with the view direction (0, 0, 1)
    hx, hy, hz = kx, ky, kz + 1.0
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx / hn, hy / hn, hz / hn
    top = len(srgb) - 1
    samples = ss * ss
    for oy in range(height):
        for ox in range(width):
            nx = 0.0
            ny = 0.0
            nz = 0.0
            r = 0.0
            g = 0.0
            bl = 0.0
            hits = 0
            for sy in range(oy * ss, oy * ss + ss):
                for sx in range(ox * ss, ox * ss + ss):
                    t = tri[sy, sx]
                    if t < 0:
                        continue
                    hits += 1
                    w0, w1 = bary[sy, sx, 0], bary[sy, sx, 1]
                    w2 = 1.0 - w0 - w1
                    a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
                    sxn = w0 * normals[a, 0] + w1 * normals[b, 0] + w2 * normals[c, 0]
                    syn = w0 * normals[a, 1] + w1 * normals[b, 1] + w2 * normals[c, 1]
                    szn = w0 * normals[a, 2] + w1 * normals[b, 2] + w2 * normals[c, 2]
                    if szn < 0.0:  # two-sided: light the side that faces the camera
                        sxn, syn, szn = -sxn, -syn, -szn
                    nx += sxn
                    ny += syn
                    nz += szn
                    r += w0 * colors[a, 0] + w1 * colors[b, 0] + w2 * colors[c, 0]
                    g += w0 * colors[a, 1] + w1 * colors[b, 1] + w2 * colors[c, 1]
                    bl += w0 * colors[a, 2] + w1 * colors[b, 2] + w2 * colors[c, 2]
            cover = hits / samples
            rest = 1.0 - cover
            if hits > 0:
                n = math.sqrt(nx * nx + ny * ny + nz * nz)
                if n > 0.0:
                    nx, ny, nz = nx / n, ny / n, nz / n
                diffuse = ambient + key * max(kx * nx + ky * ny + kz * nz, 0.0)
                diffuse += fill * max(fx * nx + fy * ny + fz * nz, 0.0)
                highlight = max(hx * nx + hy * ny + hz * nz, 0.0)
                for _ in range(doublings):
                    highlight *= highlight
                highlight *= spec * cover
                diffuse /= samples  # the colour sums are over `hits` samples: this also weights by cover
                r = r * diffuse + highlight
                g = g * diffuse + highlight
                bl = bl * diffuse + highlight
            r += rest * background[0]
            g += rest * background[1]
            bl += rest * background[2]
            out[oy, ox, 0] = srgb[min(max(int(r * top + 0.5), 0), top)]
            out[oy, ox, 1] = srgb[min(max(int(g * top + 0.5), 0), top)]
            out[oy, ox, 2] = srgb[min(max(int(bl * top + 0.5), 0), top)]


# ---------------------------------------------------------------------------------------------- colours


def _srgb_table(n: int = 4096) -> np.ndarray:
    """uint8 sRGB values of n evenly spaced linear intensities 0..1."""
    v = np.linspace(0.0, 1.0, n)
    v = np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)
    return np.round(v * 255).astype(np.uint8)


def srgb_to_linear(rgb: np.ndarray | Sequence[float]) -> np.ndarray:
    c = np.asarray(rgb, np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def heat_colors(values: np.ndarray, vmax: float) -> np.ndarray:
    """sRGB colours [N, 3] for values in [0, vmax] (clipped): grey → yellow → orange → red."""
    stops = np.asarray(HEAT_STOPS, np.float32)
    t = np.clip(np.asarray(values, np.float32) / max(float(vmax), 1e-30), 0.0, 1.0) * (len(stops) - 1)
    i = np.minimum(t.astype(np.int64), len(stops) - 2)
    frac = (t - i)[:, None]
    return stops[i] * (1 - frac) + stops[i + 1] * frac


def _lights() -> np.ndarray:
    lights = np.zeros((3, 6), np.float32)
    for row, (direction, _) in enumerate((KEY_LIGHT, FILL_LIGHT)):
        d = np.asarray(direction, np.float64)
        lights[row, :3] = d / np.linalg.norm(d)
    lights[2, :5] = KEY_LIGHT[1], FILL_LIGHT[1], AMBIENT, SPECULAR, SHININESS_DOUBLINGS
    return lights


# ---------------------------------------------------------------------------------------------- images


class Renderer:
    """Renders one mesh topology in fixed views; holds per-thread scratch buffers. Thread-safe."""

    def __init__(
        self,
        faces: np.ndarray,
        template: np.ndarray,
        size: int = 512,
        views: Sequence[str] = DEFAULT_VIEWS,
        supersample: int = 2,
    ) -> None:
        self.size = check_size(size)
        self.views = check_views(views)
        self.cameras = frame_cameras(template, self.views, self.size)
        self.ss = max(1, int(supersample))
        # triangles in screen order (16-pixel bands of the first view, left to right): neighbouring
        # triangles are drawn one after another, so the z-buffer stays in cache (~25% faster for BIWI)
        faces = np.ascontiguousarray(faces, np.int32)
        centres, _ = self.cameras[0].project(np.asarray(template, np.float64)[faces].mean(1))
        centres = np.nan_to_num(centres)
        self.faces = np.ascontiguousarray(faces[np.lexsort((centres[:, 0], centres[:, 1] // 16))])
        self.lights = _lights()
        self.background = srgb_to_linear(BACKGROUND)
        self.skin = srgb_to_linear(SKIN)
        self.srgb = _srgb_table()
        self._local = threading.local()

    @property
    def width(self) -> int:
        return self.size * len(self.views)

    def _buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        buf = getattr(self._local, "buffers", None)
        if buf is None:
            n = self.size * self.ss
            buf = (np.empty((n, n), np.int32), np.empty((n, n, 2), np.float32), np.empty((n, n), np.float32))
            self._local.buffers = buf
        return buf

    def render_into(self, vertices: np.ndarray, out: np.ndarray, colors: np.ndarray | None = None) -> None:
        """Draw every view of one frame into `out` [size, size * len(views), 3] uint8.

        colors: per-vertex sRGB [V, 3] (default: skin everywhere).
        """
        vertices = np.ascontiguousarray(vertices, np.float32)
        linear = np.empty_like(vertices)
        if colors is None:
            linear[:] = self.skin
        else:
            linear[:] = srgb_to_linear(colors)
        normals = np.empty_like(vertices)
        _vertex_normals(vertices, self.faces, normals)
        tri, bary, zbuf = self._buffers()
        xy = np.empty((len(vertices), 2), np.float32)
        inv_depth = np.empty(len(vertices), np.float32)
        view_normals = np.empty_like(vertices)
        for k, cam in enumerate(self.cameras):
            _to_view(
                vertices,
                normals,
                cam.eye.astype(np.float32),
                cam.rotation.astype(np.float32),
                cam.focal * self.ss,
                cam.size * self.ss / 2,
                xy,
                inv_depth,
                view_normals,
            )
            _rasterize(xy, inv_depth, self.faces, tri, bary, zbuf)
            _shade(
                tri,
                bary,
                self.faces,
                view_normals,
                linear,
                self.lights,
                self.background,
                self.srgb,
                self.ss,
                out[:, k * self.size : (k + 1) * self.size],
            )

    def render(self, vertices: np.ndarray, colors: np.ndarray | None = None) -> np.ndarray:
        """One frame, every view side by side: [size, size * len(views), 3] uint8 sRGB."""
        out = np.empty((self.size, self.width, 3), np.uint8)
        self.render_into(vertices, out, colors)
        return out


def check_size(size: int) -> int:
    if not isinstance(size, (int, np.integer)) or not 64 <= size <= 2048 or size % 2:
        raise FacegenError(
            f"render size must be an even number of pixels from 64 to 2048, got {size}: e.g. --size 512"
        )
    return int(size)


def warm_up() -> None:
    """Compile (or load from numba's cache) the render kernels now, e.g. at install time: a tiny render."""
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    Renderer(faces, vertices, 64).render(vertices, np.full((4, 3), 0.5, np.float32))


def render_image(
    vertices: np.ndarray,
    faces: np.ndarray,
    template: np.ndarray | None = None,
    *,
    size: int = 512,
    views: Sequence[str] = DEFAULT_VIEWS,
    colors: np.ndarray | None = None,
) -> np.ndarray:
    """One shaded image [size, size * len(views), 3] uint8 of a mesh (e.g. per-vertex values as colors)."""
    template = vertices if template is None else template
    return Renderer(faces, template, size, views).render(vertices, colors)


def write_png(image: np.ndarray, path: str | os.PathLike) -> Path:
    """Write an [H, W, 3] uint8 RGB image as PNG (atomically)."""
    image = np.ascontiguousarray(image, np.uint8)
    height, width = image.shape[:2]
    raw = b"".join(b"\x00" + image[y].tobytes() for y in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    png = (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw, 6))
        + chunk(b"IEND", b"")
    )
    with atomic_path(path) as tmp:
        tmp.write_bytes(png)
    return Path(path)


# ---------------------------------------------------------------------------------------------- text

# 5 x 7 bitmap font: 7 rows of 5 bits (hex byte each), most significant bit on the left
_FONT = {
    "A": "0E11111F111111",
    "B": "1E11111E11111E",
    "C": "0E11101010110E",
    "D": "1C12111111121C",
    "E": "1F10101E10101F",
    "F": "1F10101E101010",
    "G": "0E11101711110F",
    "H": "1111111F111111",
    "I": "0E04040404040E",
    "J": "0702020202120C",
    "K": "11121418141211",
    "L": "1010101010101F",
    "M": "111B1515111111",
    "N": "11111915131111",
    "O": "0E11111111110E",
    "P": "1E11111E101010",
    "Q": "0E11111115120D",
    "R": "1E11111E141211",
    "S": "0F10100E01011E",
    "T": "1F040404040404",
    "U": "1111111111110E",
    "V": "11111111110A04",
    "W": "1111111515150A",
    "X": "11110A040A1111",
    "Y": "11110A04040404",
    "Z": "1F01020408101F",
    "0": "0E11131519110E",
    "1": "040C040404040E",
    "2": "0E11010204081F",
    "3": "1F02040201110E",
    "4": "02060A121F0202",
    "5": "1F101E0101110E",
    "6": "0608101E11110E",
    "7": "1F010204080808",
    "8": "0E11110E11110E",
    "9": "0E11110F01020C",
    ".": "00000000000C0C",
    "-": "0000001F000000",
    "|": "04040404040404",
    "%": "18190204081303",
    ":": "000C0C000C0C00",
    "=": "00001F001F0000",
    "(": "02040808080402",
    ")": "08040202020408",
    "/": "01010204081010",
    "+": "0004041F040400",
    ",": "000000000C0408",
    "_": "0000000000001F",
    " ": "00000000000000",
    "?": "0E110102040004",
}


def draw_text(
    image: np.ndarray, text: str, x: int, y: int, scale: int = 2, color: Sequence[float] = TEXT
) -> int:
    """Draw `text` (upper-cased) into image at top-left (x, y) in a 5x7 pixel font; return the end x."""
    rgb = np.asarray(np.asarray(color) * 255 + 0.5, np.uint8)
    for ch in text.upper():
        rows = _FONT.get(ch, _FONT["?"])
        for r in range(7):
            bits = int(rows[2 * r : 2 * r + 2], 16)
            for col in range(5):
                if bits & (0x10 >> col):
                    y0, x0 = y + r * scale, x + col * scale
                    image[max(y0, 0) : max(y0 + scale, 0), max(x0, 0) : max(x0 + scale, 0)] = rgb
        x += 6 * scale
    return x


def text_width(text: str, scale: int = 2) -> int:
    return 6 * scale * len(text) - scale


def compare_overlay(
    size: int, views: int, vmax: float, face_size: float, labels: tuple[str, str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The compare video's captions, drawn once: pixel rows, columns and their RGB colours.

    A title strip names A and B at the top of each half; a line at the bottom of B's half shows the colour
    bar and its scale: "|A-B|  0 [bar] 0.0123 = 0.92% OF FACE SIZE".
    """
    canvas = np.zeros((size, 2 * size * views, 3), np.uint8)
    drawn = np.zeros(canvas.shape[:2], bool)
    scale = max(1, size // 256)
    half, pad, line = size * views, 4 * scale, 7 * scale
    fit = max(1, (half - 2 * pad) // (6 * scale))  # characters that fit in a half
    draw_text(canvas, labels[0][:fit], pad, pad, scale)
    draw_text(canvas, labels[1][:fit], half + pad, pad, scale)
    y = size - pad - line
    top = f"{_short(vmax)} = {100 * vmax / face_size:.2g}% OF FACE SIZE" if face_size > 0 else _short(vmax)
    left = draw_text(canvas, "|A-B|  0", half + pad, y, scale) + 2 * scale
    right = 2 * half - pad - text_width(top, scale)
    draw_text(canvas, top, right, y, scale)
    drawn[:] = canvas.any(-1)
    right -= 3 * scale
    if right - left > 8:
        ramp = heat_colors(np.linspace(0, 1, right - left), 1.0)
        canvas[y + scale : y + line - scale, left:right] = (ramp * 255 + 0.5).astype(np.uint8)[None]
        drawn[y + scale : y + line - scale, left:right] = True
    ys, xs = np.nonzero(drawn)
    return ys, xs, canvas[ys, xs]


def _short(value: float) -> str:
    return f"{value:.3g}"


# ---------------------------------------------------------------------------------------------- video


@dataclass
class RenderResult:
    """What a render wrote: the file, its picture size, frame count and rate, and notes for the user."""

    path: Path
    width: int
    height: int
    frames: int
    fps: float
    has_audio: bool
    seconds: float  # wall-clock time of the render
    error_scale: float | None = None  # compare mode: the heat map's top value (mesh units)
    notes: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return self.frames / self.fps


def _ffmpeg() -> str:
    import imageio_ffmpeg

    try:
        return imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as exc:  # no binary for this platform
        raise FacegenError(f"no ffmpeg binary found ({exc}): reinstall imageio-ffmpeg") from exc


def _rate(fps: float) -> str:
    return str(Fraction(fps).limit_denominator(100000))


def _clip_audio(anim: Animation, frames: int) -> np.ndarray | None:
    """The animation's audio trimmed or zero-padded to exactly `frames` frames' duration."""
    if anim.audio is None or len(anim.audio) == 0:
        return None
    n = round(frames / anim.fps * anim.sample_rate)
    audio = np.asarray(anim.audio, np.float32)[:n]
    return np.pad(audio, (0, n - len(audio))) if len(audio) < n else audio


def _encode(
    frames,
    count: int,
    width: int,
    height: int,
    fps: float,
    audio: np.ndarray | None,
    sample_rate: int,
    path: Path,
    progress: bool,
) -> None:
    """Pipe `count` rgb24 frames (an iterator of arrays) to ffmpeg and mux the audio; write `path`."""
    import soundfile as sf
    from tqdm import tqdm

    with tempfile.TemporaryDirectory(prefix="facegen-render-") as tmp:
        cmd = [
            _ffmpeg(),
            "-hide_banner",
            "-nostats",
            "-loglevel",
            "error",
            "-y",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "-s",
            f"{width}x{height}",
            "-framerate",
            _rate(fps),
            "-i",
            "pipe:0",
        ]
        if audio is not None:
            wav = Path(tmp) / "audio.wav"
            sf.write(wav, audio, int(sample_rate), subtype="FLOAT")
            cmd += [
                "-i",
                str(wav),
                "-map",
                "0:v:0",
                "-map",
                "1:a:0",
                "-c:a",
                "aac",
                "-b:a",
                "160k",
                "-ar",
                "48000",
            ]
        cmd += [
            "-c:v",
            "libx264",
            "-preset",
            "veryfast",
            "-crf",
            "18",
            "-pix_fmt",
            "yuv420p",
            "-movflags",
            "+faststart",
            str(path),
        ]
        # ffmpeg's messages go to a file, not a pipe, so it can never block on them
        with (
            open(Path(tmp) / "ffmpeg.log", "w+b") as log,
            tqdm(
                total=count, unit="frame", desc="render", disable=not progress, file=sys.stderr, leave=False
            ) as bar,
        ):
            # own session: a terminal's Ctrl-C reaches only us; we stop ffmpeg ourselves
            proc = subprocess.Popen(
                cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log, start_new_session=True
            )
            try:
                for frame in frames:
                    proc.stdin.write(frame.data)
                    bar.update(1)
                proc.stdin.close()
                code = proc.wait()
            except BrokenPipeError:
                code = proc.wait()
            except BaseException:
                proc.kill()
                proc.wait()
                raise
            if code != 0:
                log.seek(0)
                lines = log.read().decode(errors="replace").strip().splitlines()
                detail = lines[-1] if lines else f"exit code {code}"
                raise FacegenError(f"ffmpeg could not write {path.name}: {detail}; check disk space and -o")


def _frames_in_order(render_one, count: int, threads: int):
    """Render frames 0..count-1 on `threads` threads, yielding them in order (a few frames ahead)."""
    if threads <= 1:
        for t in range(count):
            yield render_one(t)
        return
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="facegen-render") as pool:
        pending: deque = deque()
        try:
            for t in range(count):
                pending.append(pool.submit(render_one, t))
                if len(pending) > FRAME_WINDOW:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:
            for future in pending:
                future.cancel()


def default_threads() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def check_output(path: str | os.PathLike) -> Path:
    path = Path(path)
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise FacegenError(
            f"cannot write a video to {path.name!r}: use a {', '.join(VIDEO_SUFFIXES)} file name "
            "(-o preview.mp4)"
        )
    check_writable(path)
    return path


def render_animation(
    anim: Animation,
    path: str | os.PathLike,
    *,
    size: int = 512,
    views: Sequence[str] = DEFAULT_VIEWS,
    compare: Animation | None = None,
    error_scale: float | None = None,
    labels: tuple[str, str] = ("A", "B"),
    progress: bool = True,
    threads: int | None = None,
    supersample: int = 2,
) -> RenderResult:
    """Render `anim` to an MP4 at its fps with its audio: the views side by side, `size` px square each.

    compare: another animation of the same topology (ground truth, another model): the video is twice as
    wide, B beside A, B painted with the per-vertex error |A - B| on a scale from 0 to `error_scale`
    (default: the clip's largest error). Frame counts that differ by a few frames use the shorter clip
    (a note in the result); a topology mismatch is a FacegenError.
    """
    start = time.perf_counter()
    path = check_output(path)
    check_animation(anim)
    _check_finite(anim, "the animation")
    notes: list[str] = []
    renderer = Renderer(anim.faces, anim.template, size, views, supersample)
    frames, audio_source = anim.num_frames, anim
    vmax = None
    if compare is not None:
        check_animation(compare)
        _check_finite(compare, "the comparison animation")
        frames = _check_comparable(anim, compare, labels, notes)
        if error_scale is not None and not error_scale > 0:
            raise FacegenError(f"the error scale must be a positive distance, got {error_scale}")
        vmax = (
            float(error_scale)
            if error_scale is not None
            else max(float(_vertex_errors(anim, compare, t).max()) for t in range(frames))
        )
        if not vmax > 0:
            vmax = max(anim.size, 1e-12) * 1e-3  # identical clips: any positive scale shows all grey
            notes.append("the two animations are identical")
        if anim.audio is None and compare.audio is not None:
            audio_source = compare
        overlay = compare_overlay(renderer.size, len(renderer.views), vmax, anim.size, labels)
    width = renderer.width * (2 if compare is not None else 1)
    height = renderer.size
    threads = default_threads() if threads is None else max(1, int(threads))

    base_colors = face_colors(anim.regions, anim.num_vertices)

    def render_one(t: int) -> np.ndarray:
        frame = np.empty((height, width, 3), np.uint8)
        renderer.render_into(anim.vertices[t], frame[:, : renderer.width], base_colors)
        if compare is not None:
            colors = heat_colors(_vertex_errors(anim, compare, t), vmax)
            renderer.render_into(compare.vertices[t], frame[:, renderer.width :], colors)
            frame[overlay[0], overlay[1]] = overlay[2]
        return frame

    audio = _clip_audio(audio_source, frames)
    if audio is None:
        notes.append("the animation has no audio: the video is silent")
    rendered = _frames_in_order(render_one, frames, threads)
    try:
        with atomic_path(path) as tmp:
            _encode(rendered, frames, width, height, anim.fps, audio, audio_source.sample_rate, tmp, progress)
    finally:
        rendered.close()  # on an error: stop the render threads before returning
    return RenderResult(
        path,
        width,
        height,
        frames,
        float(anim.fps),
        audio is not None,
        time.perf_counter() - start,
        vmax,
        notes,
    )


def _vertex_errors(a: Animation, b: Animation, t: int) -> np.ndarray:
    """|A - B| per vertex at frame t (Euclidean distance, mesh units)."""
    return np.linalg.norm(
        np.asarray(a.vertices[t], np.float32) - np.asarray(b.vertices[t], np.float32), axis=-1
    )


def _check_finite(anim: Animation, what: str) -> None:
    bad = ~np.isfinite(np.asarray(anim.vertices)).all(axis=(1, 2))
    if bad.any():
        raise FacegenError(
            f"{what} has NaN or infinite vertex positions in frame {int(np.argmax(bad))}: re-export it"
        )


def _check_comparable(a: Animation, b: Animation, labels: tuple[str, str], notes: list[str]) -> int:
    """The number of frames to compare; a FacegenError for a different topology, fps or clip."""
    name_a, name_b = labels
    if (
        a.num_vertices != b.num_vertices
        or a.faces.shape != b.faces.shape
        or not np.array_equal(a.faces, b.faces)
    ):
        raise FacegenError(
            f"cannot compare {name_a} ({a.num_vertices} vertices, {len(a.faces)} triangles) with {name_b} "
            f"({b.num_vertices} vertices, {len(b.faces)} triangles): "
            "compare animations of the same mesh topology"
        )
    if abs(a.fps - b.fps) > 1e-6:
        raise FacegenError(
            f"{name_a} is at {a.fps:g} fps but {name_b} at {b.fps:g} fps: compare clips at one "
            "frame rate (resample one, or pass --fps for .npy files)"
        )
    if a.num_frames != b.num_frames:
        shorter, longer = sorted((a.num_frames, b.num_frames))
        if longer - shorter > max(5, round(0.1 * longer)):
            raise FacegenError(
                f"{name_a} has {a.num_frames} frames but {name_b} has {b.num_frames}: these are "
                "not the same clip; compare two animations of one utterance"
            )
        notes.append(
            f"{name_a} has {a.num_frames} frames and {name_b} {b.num_frames}: comparing the first {shorter}"
        )
        return shorter
    return a.num_frames


# ---------------------------------------------------------------------------------------------- files


def load_template(template: Mesh | str | os.PathLike | None) -> Mesh | None:
    """A template given as a Mesh or a mesh file (.ply/.obj); None stays None."""
    if template is None or isinstance(template, Mesh):
        return template
    from facegen.mesh import read_mesh

    return read_mesh(template)


def read_input(
    path: str | os.PathLike, template: Mesh | None = None, fps: float | None = None, what: str = "input"
) -> Animation:
    """Read an animation file for rendering, with one-line errors for the usual mistakes."""
    from facegen.exchange import format_module, read_animation

    path = Path(path)
    format_module(path)  # unknown extension → FacegenError naming the ones facegen reads
    if not path.is_file():
        raise FacegenError(f"{what} {path} does not exist: pass an animation file facegen wrote")
    if path.suffix.lower() == ".npy" and template is None:
        raise FacegenError(
            f"{path.name} stores only vertex positions: pass --model BUNDLE or --template MESH "
            "to give its faces"
        )
    return read_animation(path, template=template, fps=fps)


def render(
    input: Animation | str | os.PathLike,
    output: str | os.PathLike,
    *,
    size: int = 512,
    views: Sequence[str] | str = DEFAULT_VIEWS,
    compare: Animation | str | os.PathLike | None = None,
    template: Mesh | str | os.PathLike | None = None,
    fps: float | None = None,
    error_scale: float | None = None,
    progress: bool = True,
    threads: int | None = None,
) -> RenderResult:
    """Render an animation (object or file: .usd*, .glb/.gltf, .npy with `template`) to a preview video.

    compare: a second animation (object or file) of the same topology: see render_animation. A .npy
    comparison file uses the input's template when `template` is not given, and the input's fps.
    fps applies to files that store none (.npy).
    """
    path = check_output(output)
    views = check_views(views)
    check_size(size)
    mesh = load_template(template)
    anim = input if isinstance(input, Animation) else read_input(input, mesh, fps)
    label_a = "A" if isinstance(input, Animation) else f"A: {Path(input).name}"
    other, label_b = None, "B"
    if compare is not None:
        if isinstance(compare, Animation):
            other = compare
        else:
            compare = Path(compare)
            label_b = f"B: {compare.name}"
            stores_fps = compare.suffix.lower() != ".npy"
            own = mesh if mesh is not None else Mesh(np.asarray(anim.template, np.float32), anim.faces)
            other = read_input(compare, own, None if stores_fps else anim.fps, what="comparison file")
    return render_animation(
        anim,
        path,
        size=size,
        views=views,
        compare=other,
        error_scale=error_scale,
        labels=(label_a, label_b),
        progress=progress,
        threads=threads,
    )


def render_still(
    input: Animation | Mesh,
    path: str | os.PathLike,
    *,
    frame: int = 0,
    size: int = 512,
    views: Sequence[str] | str = DEFAULT_VIEWS,
) -> Path:
    """Write one frame of an animation (or a mesh at rest) as a PNG, the views side by side."""
    if isinstance(input, Mesh):
        vertices, faces, template = input.vertices, input.faces, input.vertices
    else:
        if not 0 <= frame < input.num_frames:
            raise FacegenError(f"frame {frame} is outside the clip's 0..{input.num_frames - 1}")
        vertices, faces, template = input.vertices[frame], input.faces, input.template
    colors = face_colors(input.regions, len(vertices))
    image = render_image(vertices, faces, template, size=size, views=check_views(views), colors=colors)
    return write_png(image, path)
