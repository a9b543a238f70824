"""Shaded images of a mesh: camera framing, the numba z-buffer rasteriser and shader, colours, Renderer.

A z-buffer software rasteriser compiled with numba (already installed with librosa), chosen over the
GPU-style options after measuring on this 2-core, GPU-less machine with the BIWI template (46,068
triangles, one 512 x 512 view):

    numba rasteriser (this module)   ~17 ms CPU per view with 2 x 2 supersampling, on one core
                                     (z-buffer 8 ms + shading 9 ms; ~36 ms per two-view frame)
    moderngl on Mesa llvmpipe (EGL)  ~30 ms per view without anti-aliasing, ~45 ms with 4x MSAA,
                                     using both cores, plus system packages (libegl1, libgl1-mesa-dri)
    plain numpy (vectorised)         no z-buffer without a per-pixel scatter-min: far slower

The numba kernels release the GIL, so two frames render at once on two threads while ffmpeg encodes.
Nothing outside PyPI is needed: no EGL/OSMesa system libraries, no display, and the pixels are the same on
every machine (tests can reason about them). The first call on a new install compiles the kernels (a few
seconds); numba caches them beside this module (or in its user cache) for later runs.

Image: per-pixel (Phong) shading of interpolated vertex normals (face.mesh.vertex_normals, every frame),
a key light from the upper left and a fill light from the right (fixed to the camera, so every view is lit
alike), a neutral skin colour, a dark background, two-sided lighting (the mask is an open surface),
2 x 2 supersampling, sRGB output.

Camera: the face is Y up and looks +Z (BIWI's normalised convention). Each view is a yaw about the
vertical axis (front 0°, three_quarter 40° towards the subject's left, profile 90°); a 20° perspective
camera is framed once per clip from the template (its extent in every view, the same distance for all
views) so that motion shows as motion.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

from facegen.errors import FacegenError
from facegen.face.materials import MATERIALS, srgb_to_linear
from facegen.face.mesh import vertex_normals

VIEWS: dict[str, float] = {"front": 0.0, "three_quarter": 40.0, "profile": 90.0}  # yaw, degrees
DEFAULT_VIEWS = ("front", "three_quarter")
FIELD_OF_VIEW = 20.0  # degrees, vertical and horizontal (square views)
FILL = 0.84  # the template fills this fraction of a view's width or height
SKIN = MATERIALS["Skin"].srgb  # sRGB, from the one materials table (face/materials.py)
BACKGROUND = (0.08, 0.09, 0.11)  # sRGB
HEAT_STOPS = ((0.78, 0.80, 0.84), (0.99, 0.87, 0.33), (0.96, 0.50, 0.12), (0.78, 0.07, 0.07))  # sRGB, 0 → 1
# lights in view space (x right, y up, z towards the viewer): direction, intensity
KEY_LIGHT = ((-0.45, 0.55, 0.70), 0.85)
FILL_LIGHT = ((0.70, -0.05, 0.70), 0.30)
AMBIENT = 0.12
SPECULAR, SHININESS_DOUBLINGS = 0.12, 5  # Blinn exponent 2**5 = 32


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
        normals = vertex_normals(vertices, self.faces, out=np.empty_like(vertices))
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
            f"render size must be an even number of pixels from 64 to 2048, got {size}: e.g. 512",
            param="size",
        )
    return int(size)


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

