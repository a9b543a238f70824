"""The parts beside the face: eyeballs with irises and pupils, upper and lower teeth, a tongue.

They are separate meshes in the face's coordinates (its units, Y up, looking +Z); the 23,370-vertex face is
never changed. Each part is a rigid mesh about a pivot, moved per frame by a rotation and a translation (what
USD Xforms and glTF nodes carry), the tongue also by two morph targets:

- the eyes: spheres of the face's eyeball radius + EYE_MARGIN_CM at the eyeballs' fitted centres (the
  centres facegen.gaze turns the face's eyeball caps about), in front of those caps and inside the lids'
  shell; the iris and the pupil are caps of the sphere around its +Z pole, turned by the gaze rotation
  (`gaze_rotations`, the one facegen.gaze uses), so the iris points where the gaze points;
- the teeth: an arch of ten boxes each, placed along the mouth cavity's upper and lower front walls; the
  upper set is fixed to the skull, the lower set turns with the jaw about the jaw hinge's axis (x);
- the tongue: a flattened ellipsoid on the jaw behind the lower teeth; targets "tipUp" (t, d, n, l: the tip
  rises to the ridge behind the upper teeth) and "tipForward" (th and ARKit tongueOut: the tip comes
  forward between the teeth);
- the eye sockets: the skin's eye openings are wider than the eyeballs (the inner corners lie 7.7 mm beyond
  the sphere, in front of it), so a side view looked through the corner into the empty head. Each socket is
  a lining (the conjunctiva) from the opening's rim, tucked SOCKET_TUCK_CM under the skin beyond it, back
  into the eyeball: every line of sight through the opening meets the eyeball or the lining. Still, like
  the upper teeth.

The jaw's motion is not a channel of the network: `jaw_motion` finds it per frame from the chin's vertices
(deep in the rig's jaw region, where the jaw's weight is 1): the rotation about the hinge's x axis and the
translation that carry the chin's rest points best onto the frame's (2-D Procrustes in y-z).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from facegen.face.rig import eyeballs, face_scale

EYE_MARGIN_CM = 0.05  # the part eyeball's radius over the face's eyeball cap (lids' shell: +0.13 cm)
IRIS_CM, PUPIL_CM = 0.58, 0.21  # radii
UPPER_TEETH = (0.78, 0.62, 0.72, 0.66, 0.66)  # widths (cm) from the midline out, each side
LOWER_TEETH = (0.55, 0.58, 0.64, 0.66, 0.70)
TOOTH_DEPTH = 0.28  # cm front to back
TONGUE_CM = (1.55, 0.33, 1.2)  # semi-axes x, y, z
TONGUE_RAISE_CM, TONGUE_FORWARD_CM = 0.8, 0.45
SOCKET_TUCK_CM, SOCKET_DEPTH_CM = 0.2, 0.05  # the lining's reach under the skin past the rim, and its depth
PART_NAMES = ("LeftEye", "RightEye", "UpperTeeth", "LowerTeeth", "Tongue", "EyeSockets")


@dataclass
class Part:
    """One mesh beside the face: `vertices` [N, 3] about `pivot` (face units), triangles `faces` [F, 3];
    `groups` (material name, first triangle, end) cover the triangles in order, each group with vertices
    of its own (so a vertex has one material: `vertex_materials`); `targets` {name: [N, 3] offsets}."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    groups: list[tuple[str, int, int]]
    pivot: np.ndarray
    targets: dict[str, np.ndarray] = field(default_factory=dict)

    def vertex_materials(self) -> np.ndarray:
        out = np.empty(len(self.vertices), dtype=object)
        for name, a, b in self.groups:
            out[np.unique(self.faces[a:b])] = name
        return out


@dataclass
class PartDrivers:
    """What moves the parts besides the face's own frames: the gaze (yaw, pitch) degrees [T, 2]
    (facegen.gaze) and the tongue's target weights [T, 2] (tipUp, tipForward; facegen.tongue)."""

    gaze: np.ndarray
    tongue: np.ndarray


@dataclass
class PartTrack:
    """A part and its motion: `rotation` [T, 3, 3] and `translation` [T, 3] (where its pivot is), target
    `weights` [T, K] (None: no targets)."""

    part: Part
    rotation: np.ndarray
    translation: np.ndarray
    weights: np.ndarray | None = None

    def points(self, t: int) -> np.ndarray:
        """The part's vertices at frame `t` in the face's coordinates, [N, 3] float64."""
        local = np.asarray(self.part.vertices, np.float64)
        if self.weights is not None:
            for k, offsets in enumerate(self.part.targets.values()):
                local = local + float(self.weights[t, k]) * offsets
        return self.translation[t] + local @ self.rotation[t].T


def gaze_rotations(yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """[n, 3, 3] rotations of gaze angles in radians: yaw about +y (+ turns +z toward +x, the character's
    left), then pitch about x (+ turns +z up)."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(-pitch), np.sin(-pitch)
    ry = np.zeros((len(yaw), 3, 3))
    ry[:, 0, 0], ry[:, 0, 2], ry[:, 1, 1], ry[:, 2, 0], ry[:, 2, 2] = cy, sy, 1, -sy, cy
    rx = np.zeros((len(yaw), 3, 3))
    rx[:, 0, 0], rx[:, 1, 1], rx[:, 1, 2], rx[:, 2, 1], rx[:, 2, 2] = 1, cp, -sp, sp, cp
    return ry @ rx


def x_rotations(angle: np.ndarray) -> np.ndarray:
    """[n, 3, 3] rotations about +x by `angle` rad (+ moves points in front, +z, down: the jaw opening)."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((len(angle), 3, 3))
    out[:, 0, 0], out[:, 1, 1], out[:, 1, 2], out[:, 2, 1], out[:, 2, 2] = 1, c, -s, s, c
    return out


def quaternions(rotation: np.ndarray) -> np.ndarray:
    """[n, 4] unit quaternions (x, y, z, w; glTF's order, w >= 0) of rotation matrices [n, 3, 3] (without
    scipy.spatial: its import costs half a second)."""
    r = np.asarray(rotation, np.float64)
    w = np.sqrt(np.maximum(0.0, 1 + r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2])) / 2
    x = np.sqrt(np.maximum(0.0, 1 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2])) / 2
    y = np.sqrt(np.maximum(0.0, 1 - r[:, 0, 0] + r[:, 1, 1] - r[:, 2, 2])) / 2
    z = np.sqrt(np.maximum(0.0, 1 - r[:, 0, 0] - r[:, 1, 1] + r[:, 2, 2])) / 2
    x = np.copysign(x, r[:, 2, 1] - r[:, 1, 2])
    y = np.copysign(y, r[:, 0, 2] - r[:, 2, 0])
    z = np.copysign(z, r[:, 1, 0] - r[:, 0, 1])
    q = np.stack([x, y, z, w], 1)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def has_parts(regions: dict) -> bool:
    """Whether a face names what the parts are fitted to (facegen's procedural faces do)."""
    return all(r in regions for r in ("left_eyeball", "right_eyeball", "mouth_cavity", "mouth_upper_margin",
                                      "mouth_lower_margin", "jaw", "jaw_hinge"))


# ------------------------------------------------------------------------------------------- geometry


def _group_mesh(pieces: list[tuple[str, np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray, list]:
    """Concatenate (material, vertices, faces) pieces of one material each into one mesh and its groups,
    pieces of the same material next to each other."""
    order = sorted(range(len(pieces)), key=lambda i: [p[0] for p in pieces].index(pieces[i][0]))
    verts, faces, groups = [], [], []
    nv = nf = 0
    for i in order:
        name, v, f = pieces[i]
        verts.append(v)
        faces.append(f + nv)
        if groups and groups[-1][0] == name:
            groups[-1] = (name, groups[-1][1], nf + len(f))
        else:
            groups.append((name, nf, nf + len(f)))
        nv += len(v)
        nf += len(f)
    return np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.int32), groups


def _sphere_band(radius: float, theta0: float, theta1: float, rings: int, segments: int = 32):
    """A band of a sphere about +Z between polar angles theta0..theta1 (closed by a pole where theta0 is 0
    or theta1 is pi): vertices, outward triangles."""
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    thetas = np.linspace(theta0, theta1, rings + 1)
    first_pole, last_pole = theta0 <= 0, theta1 >= np.pi
    ring_angles = thetas[int(first_pole):len(thetas) - int(last_pole)]
    rows = [np.stack([radius * np.sin(th) * np.cos(phi), radius * np.sin(th) * np.sin(phi),
                      np.full(segments, radius * np.cos(th))], 1) for th in ring_angles]
    offset = 1 if first_pole else 0
    parts = ([np.array([[0.0, 0.0, radius]])] if first_pole else []) + rows
    if last_pole:
        parts.append(np.array([[0.0, 0.0, -radius]]))
    v = np.concatenate(parts)
    ring = np.arange(segments)
    nxt = (ring + 1) % segments
    tris = []
    if first_pole:
        tris.append(np.stack([np.zeros(segments, int), 1 + ring, 1 + nxt], 1))
    for r in range(len(rows) - 1):
        a = offset + r * segments
        b = a + segments
        tris += [np.stack([a + ring, b + ring, b + nxt], 1), np.stack([a + ring, b + nxt, a + nxt], 1)]
    if last_pole:
        a = offset + (len(rows) - 1) * segments
        tris.append(np.stack([a + ring, np.full(segments, len(v) - 1), a + nxt], 1))
    return v, np.concatenate(tris)


def _eye(name: str, centre: np.ndarray, radius: float, cm: float) -> Part:
    pupil = float(np.arcsin(min(PUPIL_CM * cm / radius, 0.9)))
    iris = float(np.arcsin(min(IRIS_CM * cm / radius, 0.95)))
    pieces = [("Pupil", *_sphere_band(radius, 0.0, pupil, 2)),
              ("Iris", *_sphere_band(radius, pupil, iris, 4)),
              ("EyeWhite", *_sphere_band(radius, iris, np.pi, 14))]
    v, f, groups = _group_mesh(pieces)
    return Part(name, v, f, groups, np.asarray(centre, np.float32))


def _box(centre: np.ndarray, across: np.ndarray, up: np.ndarray, back: np.ndarray,
         size: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """A box (24 vertices: flat sides) at `centre` with half-sizes `size` along unit `across`, `up`,
    `back`; its triangles face out."""
    w, h, d = (s / 2 for s in size)
    axes = (across * w, up * h, back * d)
    verts, tris = [], []
    for k in range(3):
        for sign in (1, -1):
            n = axes[k] * sign
            a, b = axes[(k + 1) % 3], axes[(k + 2) % 3]
            quad = [centre + n + sa * a + sb * b for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            base = len(verts)
            verts += quad
            tri = [[base, base + 1, base + 2], [base, base + 2, base + 3]]
            if np.dot(np.cross(quad[1] - quad[0], quad[2] - quad[0]), n) < 0:
                tri = [[t[0], t[2], t[1]] for t in tri]
            tris += tri
    return np.asarray(verts), np.asarray(tris)


def _wall(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The depth of a cavity wall across the mouth: (sorted x, mean z at each x)."""
    x = np.round(points[:, 0], 6)
    xs = np.unique(x)
    return xs, np.array([points[x == u, 2].mean() for u in xs])


def _arch(wall: tuple[np.ndarray, np.ndarray], widths: tuple[float, ...], front: float, y0: float,
          height: float, cm: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Teeth along a wall curve z(x) (cm, mouth-centred): their fronts `front` cm in front of the wall,
    tops/bottoms from y0 over `height` (negative: downwards); boxes mirrored about x = 0."""
    xs, zs = wall
    fine = np.linspace(0, xs.max(), 400)
    z = np.interp(fine, xs, zs) + front
    arc = np.concatenate([[0], np.cumsum(np.hypot(np.diff(fine), np.diff(z)))])
    out = []
    s = 0.0
    for w in widths:
        mid = s + w / 2
        x = float(np.interp(mid, arc, fine))
        dz = float(np.interp(mid + 0.05, arc, z) - np.interp(mid - 0.05, arc, z))
        dx = float(np.interp(mid + 0.05, arc, fine) - np.interp(mid - 0.05, arc, fine))
        t = np.array([dx, 0, dz]) / np.hypot(dx, dz)
        back = np.array([t[2], 0, -t[0]])  # toward the inside of the arch (-z at the midline)
        zf = float(np.interp(x, fine, z))
        for side in (1, -1):
            mirror = np.array([side, 1, 1])
            centre = np.array([x, y0 + height / 2, zf]) * mirror + back * mirror * TOOTH_DEPTH / 2
            out.append(_box(centre * cm, t * mirror, np.array([0, 1.0, 0]), back * mirror,
                            (w * 0.94 * cm, abs(height) * cm, TOOTH_DEPTH * cm)))
        s += w
    return out


def _tongue(cm: float) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """The tongue about its centre: a flattened ellipsoid (cm semi-axes TONGUE_CM) and its targets."""
    v, f = _sphere_band(1.0, 0.0, np.pi, 16, 24)
    a = np.asarray(TONGUE_CM)
    local = v * a
    front = np.clip((local[:, 2] + 0.2 * a[2]) / (1.2 * a[2]), 0, 1) ** 2  # 0 behind, 1 at the tip
    upper = np.clip(local[:, 1] / a[1] + 1, 0, 2) / 2
    up = np.zeros_like(local)
    up[:, 1] = TONGUE_RAISE_CM * front * (0.5 + 0.5 * upper)
    up[:, 2] = 0.1 * front
    forward = np.zeros_like(local)
    forward[:, 2] = TONGUE_FORWARD_CM * front
    forward[:, 1] = 0.15 * front
    forward[:, 0] = -0.25 * local[:, 0] * front
    targets = {"tipUp": (up * cm).astype(np.float32), "tipForward": (forward * cm).astype(np.float32)}
    return (local * cm).astype(np.float32), f.astype(np.int32), targets


def eye_rims(template: np.ndarray, faces: np.ndarray, regions: dict[str, np.ndarray],
             centres: np.ndarray) -> list[np.ndarray]:
    """Each eye's opening in the skin: the face's vertex indices around it, in order along the loop (the
    skin's boundary loop nearest each eyeball centre; the eyeball caps and the mouth cavity left out)."""
    f = np.asarray(faces, np.int64)
    inner = np.zeros(len(template), bool)
    for r in ("left_eyeball", "right_eyeball", "mouth_cavity"):
        inner[np.asarray(regions[r], np.int64)] = True
    f = f[~inner[f].any(1)]
    pairs = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    keys, counts = np.unique(pairs[:, 0] * len(template) + pairs[:, 1], return_counts=True)
    nxt: dict[int, list[int]] = {}
    for a, b in zip(*np.divmod(keys[counts == 1], len(template)), strict=True):
        a, b = int(a), int(b)
        nxt.setdefault(a, []).append(b)
        nxt.setdefault(b, []).append(a)
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, prev, cur = [start], -1, start
        while True:
            seen.add(cur)
            step = next((n for n in nxt[cur] if n != prev), None)
            if step is None or step in seen:  # back at the start (or at a vertex met before)
                break
            loop.append(step)
            prev, cur = cur, step
        loops.append(np.asarray(loop, np.int64))
    t = np.asarray(template, np.float64)
    return [min(loops, key=lambda lp: float(np.linalg.norm(t[lp].mean(0) - c))) for c in centres]


def _socket(template: np.ndarray, normals: np.ndarray, rim: np.ndarray, centre: np.ndarray, radius: float,
            cm: float) -> tuple[np.ndarray, np.ndarray]:
    """One eye's socket lining: three loops along the rim (tucked under the skin beyond it, just behind
    the rim, inside the eyeball) joined by quads; its triangles face the opening."""
    t, n = np.asarray(template, np.float64)[rim], normals[rim]
    out = t - t.mean(0)
    out -= (out * n).sum(1, keepdims=True) * n  # away from the opening, along the skin
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    behind = t - SOCKET_DEPTH_CM * cm * n
    ray = behind - centre
    inside = centre + 0.85 * radius * ray / np.linalg.norm(ray, axis=1, keepdims=True)
    loops = [behind + SOCKET_TUCK_CM * cm * out, behind, inside]
    k = len(rim)
    i, j = np.arange(k), (np.arange(k) + 1) % k
    tris = np.concatenate([np.concatenate([np.stack([a + i, a + j, a + k + j], 1),
                                           np.stack([a + i, a + k + j, a + k + i], 1)]) for a in (0, k)])
    v = np.concatenate(loops)
    a, b, c = v[tris[:, 0]], v[tris[:, 1]], v[tris[:, 2]]
    facing = (np.cross(b - a, c - a) * (centre + 2 * radius * n.mean(0) - (a + b + c) / 3)).sum(1)
    return v, (tris if np.sum(facing > 0) >= len(tris) / 2 else tris[:, ::-1])


def face_parts(template: np.ndarray, regions: dict[str, np.ndarray], faces: np.ndarray) -> list[Part]:
    """The parts of a face (its rest pose `template`, `regions`, see `has_parts`, and triangles `faces`), in
    PART_NAMES order."""
    t = np.asarray(template, np.float64)
    reg = {k: np.asarray(v, np.int64) for k, v in regions.items()}
    centres, axes = eyeballs(t, reg)
    _, cm = face_scale(t, reg)
    radii = [float(a[1:].min()) + EYE_MARGIN_CM * cm for a in axes]
    parts = [_eye(name, c, r, cm) for name, c, r in zip(("LeftEye", "RightEye"), centres, radii, strict=True)]
    mouth = (t[reg["mouth_upper_margin"]].mean(0) + t[reg["mouth_lower_margin"]].mean(0)) / 2
    cav = (t[reg["mouth_cavity"]] - mouth) / cm
    upper_wall = _wall(cav[cav[:, 1] > 0.45])
    lower_wall = _wall(cav[cav[:, 1] < -0.45])
    upper = _arch(upper_wall, UPPER_TEETH, -0.06, -0.22, 1.0, cm)  # hangs below the slit
    lower = _arch(lower_wall, LOWER_TEETH, -0.38, -0.08, -0.85, cm)  # behind the upper set (overbite)
    hinge = t[reg["jaw_hinge"]].mean(0)
    for name, boxes, pivot in (("UpperTeeth", upper, mouth), ("LowerTeeth", lower, hinge)):
        v, f, groups = _group_mesh([("Teeth", b[0] + (mouth - pivot), b[1]) for b in boxes])
        parts.append(Part(name, v, f, groups, pivot.astype(np.float32)))
    tv, tf, targets = _tongue(cm)
    z_front = float(np.interp(0.0, *lower_wall)) - 0.38 - TOOTH_DEPTH - 0.1
    centre = mouth + np.array([0.0, -0.38, z_front - TONGUE_CM[2]]) * cm
    parts.append(Part("Tongue", tv + (centre - hinge).astype(np.float32), tf, [("Tongue", 0, len(tf))],
                      hinge.astype(np.float32), targets))
    rims = eye_rims(t, faces, reg, centres)
    around = np.asarray(faces, np.int64)
    around = around[np.isin(around, np.concatenate(rims)).any(1)]  # the rims' triangles: their normals
    cross = np.cross(t[around[:, 1]] - t[around[:, 0]], t[around[:, 2]] - t[around[:, 0]])
    normals = np.zeros_like(t)  # area-weighted, as face/mesh.py's vertex_normals (without loading numba)
    for k in range(3):
        np.add.at(normals, around[:, k], cross)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    between = centres.mean(0)
    sockets = [_socket(t, normals, rim, c, r, cm) for rim, c, r in zip(rims, centres, radii, strict=True)]
    v, f, groups = _group_mesh([("Conjunctiva", sv - between, sf) for sv, sf in sockets])
    parts.append(Part("EyeSockets", v, f, groups, between.astype(np.float32)))
    return parts


# ---------------------------------------------------------------------------------------------- motion


def chin_points(template: np.ndarray, regions: dict[str, np.ndarray]) -> np.ndarray:
    """The vertices the jaw's motion is read from: the jaw region's skin 2-4 cm below the mouth, within
    1.5 cm of the midline (where the rig's jaw weight is 1)."""
    t = np.asarray(template, np.float64)
    _, cm = face_scale(t, regions)
    mouth = (t[regions["mouth_upper_margin"]].mean(0) + t[regions["mouth_lower_margin"]].mean(0)) / 2
    jaw = np.setdiff1d(np.asarray(regions["jaw"], np.int64), np.asarray(regions["mouth_cavity"], np.int64))
    rel = (t[jaw] - mouth) / cm
    return jaw[(np.abs(rel[:, 0]) < 1.5) & (rel[:, 1] < -2.0) & (rel[:, 1] > -4.0)]


def jaw_motion(rest: np.ndarray, frames: np.ndarray, hinge: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The jaw's angle about the hinge's x axis [T] (rad, + opens) and where the hinge goes [T, 3], from the
    chin's rest points `rest` [n, 3] and their positions in each frame `frames` [T, n, 3]."""
    rest = np.asarray(rest, np.float64)
    frames = np.asarray(frames, np.float64)
    u = rest - rest.mean(0)
    v = frames - frames.mean(1, keepdims=True)
    cross = (u[None, :, 1] * v[:, :, 2] - u[None, :, 2] * v[:, :, 1]).sum(1)
    dot = (u[None, :, 1] * v[:, :, 1] + u[None, :, 2] * v[:, :, 2]).sum(1)
    angle = np.arctan2(cross, dot)
    rot = x_rotations(angle)
    hinge = np.asarray(hinge, np.float64)
    moved = hinge + np.einsum("tij,j->ti", rot, rest.mean(0) - hinge)  # the rest centroid turned
    return angle, hinge + frames.mean(1) - moved


def part_tracks(parts: list[Part], drivers: PartDrivers, jaw_angle: np.ndarray,
                hinge_at: np.ndarray) -> list[PartTrack]:
    """Every part's motion over T frames: the eyes turned by the gaze about their centres, the upper teeth
    and the eye sockets still, the lower teeth and the tongue with the jaw (`jaw_angle` [T], `hinge_at`
    [T, 3]), the tongue's targets weighted by the drivers."""
    T = len(jaw_angle)
    gaze = np.radians(np.asarray(drivers.gaze, np.float64)).reshape(T, 2)
    eye_rot = gaze_rotations(gaze[:, 0], gaze[:, 1])
    jaw_rot = x_rotations(np.asarray(jaw_angle, np.float64))
    still = np.broadcast_to(np.eye(3), (T, 3, 3))
    out = []
    for part in parts:
        pivot = np.broadcast_to(np.asarray(part.pivot, np.float64), (T, 3))
        if part.name in ("LeftEye", "RightEye"):
            out.append(PartTrack(part, eye_rot, pivot))
        elif part.name in ("UpperTeeth", "EyeSockets"):
            out.append(PartTrack(part, still, pivot))
        else:
            weights = np.asarray(drivers.tongue, np.float64).reshape(T, 2) if part.targets else None
            out.append(PartTrack(part, jaw_rot, np.asarray(hinge_at, np.float64), weights))
    return out


def skin_clearance(frame: np.ndarray, faces: np.ndarray, regions: dict[str, np.ndarray],
                   points: np.ndarray) -> np.ndarray:
    """How far each of `points` [n, 3] lies behind the skin of the face's `frame` [V, 3] (without its
    eyeball caps and mouth cavity), looking from the front (along -z): the depth to the nearest skin in
    front of it; a point with no skin in front but skin behind it pokes through (negative: how far in front
    of that skin); a point with neither is seen through an opening (the mouth, the eyes' slits): +inf.
    The measure of tests/test_parts.py and benchmarks/bench_face_parts.py."""
    from scipy.spatial import cKDTree

    frame = np.asarray(frame, np.float64)
    points = np.asarray(points, np.float64)
    hidden = np.zeros(len(frame), bool)
    for r in ("left_eyeball", "right_eyeball", "mouth_cavity"):
        hidden[np.asarray(regions[r], np.int64)] = True
    f = np.asarray(faces, np.int64)
    f = f[~hidden[f].any(1)]
    tri = frame[f]  # [F, 3, 3]
    reach = float(np.linalg.norm(tri[:, :, :2] - tri[:, :, :2].mean(1, keepdims=True), axis=2).max())
    near = cKDTree(tri[:, :, :2].mean(1)).query_ball_point(points[:, :2], reach)
    out = np.full(len(points), np.inf)
    for i, cands in enumerate(near):
        if not cands:
            continue
        a, b, c = (tri[cands, k] for k in range(3))
        v0, v1, v2 = b[:, :2] - a[:, :2], c[:, :2] - a[:, :2], points[i, :2] - a[:, :2]
        den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
        ok = np.abs(den) > 1e-18
        u = np.where(ok, (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / np.where(ok, den, 1), -1)
        w = np.where(ok, (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / np.where(ok, den, 1), -1)
        inside = (u >= 0) & (w >= 0) & (u + w <= 1)
        if not inside.any():
            continue
        z = (a[:, 2] + u * (b[:, 2] - a[:, 2]) + w * (c[:, 2] - a[:, 2]))[inside] - points[i, 2]
        out[i] = z[z >= 0].min() if (z >= 0).any() else z.max()
    return out
