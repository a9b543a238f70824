"""A motion rig on the procedural face: channel weights [T, C] -> vertex positions.

`Rig(mesh)` precomputes smooth per-vertex weights (falloffs of the graph distance over the mesh from
the named regions of facegen.face.procedural) and poses the face from channel weights [T, C]:

* linear offsets (lip shapes, brows, cheeks),
* the jaw: a rotation about the hinge axis, the lower lip and lower mouth cavity with it,
* the lids: rotations about each eyeball's centre (blink closes each lid column exactly),
* lip_close: the lips meet along the slit whatever the jaw does (p, b, m).

The curves that drive it come from timings (facegen.synth.curves). `face_scale` gives any face's eyeball
centres and its mesh units per cm, the physical unit the rig and the lip-sync metrics measure in.
"""

from __future__ import annotations

import numpy as np

from facegen.errors import FacegenError
from facegen.face.mesh import Mesh
from facegen.face.regions import RIG_REGIONS

LOWER_CHANNELS = ("jaw_open", "lip_close", "lip_round", "lip_wide", "lip_funnel", "lower_lip_tuck",
                  "upper_lip_raise")
UPPER_CHANNELS = ("brow_raise", "brow_frown", "lid_widen", "cheek_raise")
BLINK_CHANNELS = ("blink",)
CHANNELS = LOWER_CHANNELS + UPPER_CHANNELS + BLINK_CHANNELS

# expression classes of the lexicon -> upper-face channel amounts
EXPRESSIONS: dict[str, dict[str, float]] = {
    "surprise": {"brow_raise": 1.0, "lid_widen": 0.4},
    "anger": {"brow_frown": 1.0},
    "sadness": {"brow_frown": 0.55, "brow_raise": 0.25},
    "fear": {"lid_widen": 1.0, "brow_raise": 0.5},
    "awe": {"lid_widen": 0.7, "brow_raise": 0.7},
    "joy": {"cheek_raise": 1.0},
}

EYE_SPACING_CM = 6.3  # distance between the eyeball centres of the canonical face
# jaw_open = 1 parts the lips by about 2 cm: the jaw turns JAW_MAX_ANGLE and the lower lip is drawn down
# LIP_DROP_CM further on its own (depressor labii inferioris), as a real capture's lower lip is
# (mouthLowerDown follows jawOpen at r 0.68 there). The split is set on that capture
# (benchmarks/calibrate_lip_drop.py, docs/arkit_capture.md): with 15 % of the opening the lower lip's own,
# the model trained on the rig draws the lower lip down nearly as far as the capture (mouthLowerDown's range
# 0.84x) and its jawOpen ranges 1.25x the capture's; the rig alone draws it 1.2x as far (95th percentile
# 0.44 against 0.36). A tenth (0.291 rad, 0.21 cm) matched the rig alone, and the network drew the lip half
# as far; the jaw alone turned 0.33 rad before that.
JAW_MAX_ANGLE = 0.273  # rad
LIP_DROP_CM = 0.31
LOWER_LIP_FORWARD = 0.15  # cm the lower lip comes forward per cm it is drawn down (it everts)
ROUND_FORWARD = 0.4  # cm the skin beside the mouth's corners comes forward at full rounding (lip_round)
# How far rounding draws the mouth's corners in and spreading draws them out: each corner moves across the
# face by this fraction of its distance from the mouth's centre at full lip_round / lip_wide. Set on GRID's
# speakers (benchmarks/calibrate_width.py, docs/real_faces.md, tenth pass): at their vowels' middles the
# tracked mouth is 0.25 cm narrower than at rest for rounded vowels (UW 0.40), 0.03 cm wider for spread ones
# (IY 0.10); the rig posed from the same clips' phones gives -0.35 (UW -0.43), +0.04 (IY +0.11). Before this
# (0.36 and 0.24, set by eye) it gave -1.13 (UW -1.39) and +0.29 (IY +0.60).
ROUND_NARROW = 0.11
WIDE_SPREAD = 0.05
# The mouth's full stretch (ARKit's mouthStretch): the corners out by this fraction of their distance from
# the centre, the lips thinned and drawn back. Speech's spreading (lip_wide) is WIDE_SPREAD / STRETCH_SPREAD
# of it, all of it, so that ARKit's fit reads a spread vowel as a part of a stretch (with only its width
# scaled, the fit read the thinned, drawn-back lips as mouthRollUpper 0.5, mouthRollLower 0.4, mouthDimple
# 0.3).
STRETCH_SPREAD = 0.24


def falloff(d: np.ndarray, radius: float) -> np.ndarray:
    """1 at distance 0, smoothly 0 at `radius` and beyond (inf -> 0)."""
    t = np.clip(1.0 - np.nan_to_num(d, posinf=1e9) / radius, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def rotate_x(pos: np.ndarray, idx: np.ndarray, centre: np.ndarray, angle: np.ndarray) -> None:
    """Rotate the vertices `idx` of pos [T, V, 3] in place about x-parallel axes through `centre`
    ([3] or [len(idx), 3]) by `angle` [T, len(idx)] rad; positive angles move points in front of the
    centre (+z) downwards (-y)."""
    c, s = np.cos(angle), np.sin(angle)
    centre = np.broadcast_to(centre, (len(idx), 3))
    y = pos[:, idx, 1] - centre[None, :, 1]
    z = pos[:, idx, 2] - centre[None, :, 2]
    pos[:, idx, 1] = centre[None, :, 1] + y * c - z * s
    pos[:, idx, 2] = centre[None, :, 2] + y * s + z * c


def _fit_centre(points: np.ndarray) -> np.ndarray:
    """Centre of the axis-aligned ellipsoid through `points` (least squares)."""
    p = np.asarray(points, np.float64)
    a = np.concatenate([p**2, p], 1)
    coef, *_ = np.linalg.lstsq(a, np.ones(len(p)), rcond=None)
    return -coef[3:] / (2 * coef[:3])


def face_scale(vertices: np.ndarray, regions: dict[str, np.ndarray]) -> tuple[np.ndarray, float]:
    """The eyeball centres [2, 3] (left, right; fitted ellipsoids) of a face with the regions
    `left_eyeball` and `right_eyeball`, and its mesh units per cm (their distance / EYE_SPACING_CM)."""
    t = np.asarray(vertices, np.float64)
    centres = np.stack([_fit_centre(t[np.asarray(regions[f"{side}_eyeball"], np.int64)])
                        for side in ("left", "right")])
    return centres, float(np.linalg.norm(centres[0] - centres[1])) / EYE_SPACING_CM


def _fit_axes(points: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Semi-axes of the axis-aligned ellipsoid about `centre` through `points` (least squares)."""
    d = (np.asarray(points, np.float64) - centre) ** 2
    inv_sq, *_ = np.linalg.lstsq(d, np.ones(len(d)), rcond=None)
    return 1 / np.sqrt(inv_sq)


def eyeballs(vertices: np.ndarray, regions: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The eyeballs' fitted centres and semi-axes, [2, 3] each (left, right), of a face with the regions
    `left_eyeball` and `right_eyeball` (what the Rig and facegen.gaze turn them about)."""
    t = np.asarray(vertices, np.float64)
    centres, _ = face_scale(t, regions)
    axes = np.stack([_fit_axes(t[np.asarray(regions[f"{s}_eyeball"], np.int64)], c)
                     for s, c in zip(("left", "right"), centres, strict=True)])
    return centres, axes


class Rig:
    """Deformers on a face made by facegen.face.procedural (any speaker: the regions carry the layout).

    Besides posing, it keeps what other deformers of the face build on (facegen.arkit.shapes): `cm` (mesh
    units per cm), `distance` (graph distance in cm) and `smooth`, the per-vertex weight fields in `fields`
    (mouth: `mouth_x` cm across the mouth from its centre, `upper_side`, `d_up`/`d_lo`/`d_m` cm from the
    upper / lower / either lip margin, `lat`, `lat_wide`, `near`, `peri`, `w_up`, `w_lo`, `lower_lip` (the
    lower lip as jaw_open and mouthLowerDown draw it down); `brow`, `corner` and `cheek`
    with their distances `d_corner` and `d_cheek`, `squint` (below the lower lids), `jaw` (the jaw's
    rotation weight)), `mouth_centre` (mesh units), `mouth_half` (cm), the eyeballs' `eye_centres` /
    `eye_axes` and the lid rotation arrays (`lid_idx`, `lid_upper`, `lid_w`, `lid_alpha`: the angle that
    closes each lid column, `lid_centre`) used with `rotate_x`.
    """

    channels: tuple[str, ...] = CHANNELS

    def __init__(self, mesh: Mesh) -> None:
        missing = [r for r in RIG_REGIONS if r not in mesh.regions]
        if missing:
            raise FacegenError(f"the mesh lacks the rig regions {', '.join(missing)}: "
                               "use a face from facegen.face.procedural (make_face or speaker_face)")
        self.template = np.asarray(mesh.vertices, np.float64)
        self.faces = np.asarray(mesh.faces)
        reg = {k: np.asarray(v, np.int64) for k, v in mesh.regions.items()}
        V = len(self.template)
        t = self.template
        # scale: mesh units per cm, from the distance between the eyeball centres
        _, cm = face_scale(t, reg)
        self.eye_centres, self.eye_axes = eyeballs(t, reg)
        self.cm = cm
        self._graph = self._build_graph()
        dist = self.distance

        mu, ml = reg["mouth_upper_margin"], reg["mouth_lower_margin"]
        d_up, src_up = dist(mu, True)
        d_lo, src_lo = dist(ml, True)
        mouth_centre = (t[mu].mean(0) + t[ml].mean(0)) / 2
        X = (t[:, 0] - mouth_centre[0]) / cm  # cm across the mouth
        half = (t[mu[-1], 0] - t[mu[0], 0]) / 2 / cm  # mouth half-width, cm
        upper_side = d_up < d_lo
        d_m = np.minimum(d_up, d_lo)
        lat = np.sqrt(np.clip(1 - (X / (half + 0.2)) ** 2, 0, 1))

        off: dict[str, np.ndarray] = {}

        def field(dx=0.0, dy=0.0, dz=0.0) -> np.ndarray:
            return np.stack([np.broadcast_to(dx, (V,)), np.broadcast_to(dy, (V,)),
                             np.broadcast_to(dz, (V,))], 1) * cm

        sm = self.smooth
        near = sm(falloff(d_m, 0.9))  # the lips themselves
        peri = sm(falloff(d_m, 2.4))  # lips and the skin around them
        w_up = sm(falloff(d_up, 1.5) * upper_side)
        w_lo = sm(falloff(d_lo, 1.5) * ~upper_side)
        sgn = np.where(upper_side, 1.0, -1.0)
        opening = np.clip(1 - (X / half) ** 2, 0, 1)
        off["lip_close"] = field(dz=-0.12 * sm(falloff(d_m, 0.6)))  # pressed (the seal itself is below)
        Xc = np.clip(X, -half, half)
        peri_round = sm(falloff(d_m, 1.9))
        wide_round = sm(falloff(d_m, 3.0))
        # rounding narrows the mouth and brings it forward: the skin beside the corners comes forward as it
        # is drawn in (ROUND_FORWARD), else it would pass into the dental arch (a held OW: 1.7 mm into the
        # canines)
        forward = ROUND_FORWARD * np.abs(Xc) / half * wide_round
        off["lip_round"] = field(dx=-ROUND_NARROW * Xc * wide_round, dy=sgn * 0.22 * near * opening**0.7,
                                 dz=0.5 * peri_round**2 + 0.25 * near + forward)
        stretch = field(dx=STRETCH_SPREAD * Xc * peri, dy=0.12 * (X / half) ** 2 * peri - sgn * 0.05 * near,
                        dz=-0.18 * peri)
        off["lip_wide"] = WIDE_SPREAD / STRETCH_SPREAD * stretch
        off["lip_funnel"] = field(dx=-0.18 * Xc * peri, dy=sgn * 0.3 * near * opening**0.3,
                                  dz=0.5 * peri**2 + 0.15 * near)
        off["lower_lip_tuck"] = field(dy=0.38 * w_lo * lat + 0.06 * w_up * lat, dz=-0.5 * w_lo * lat)
        off["upper_lip_raise"] = field(dy=0.32 * w_up * lat, dz=0.12 * w_up * lat)
        # the lower lip drawn down (ARKit's mouthLowerDown): the jaw's own drop of it
        lat_wide = np.sqrt(np.clip(1 - (X / (half + 1.0)) ** 2, 0, 1))
        lower_lip = sm(falloff(d_lo, 2.0) * ~upper_side) * lat_wide
        self._lip_drop = field(dy=-LIP_DROP_CM * lower_lip,
                               dz=LOWER_LIP_FORWARD * LIP_DROP_CM * lower_lip).astype(np.float32)

        # upper face
        d_brow = dist(reg["brows"])
        w_brow = sm(falloff(d_brow, 1.3))
        Y = (t[:, 1] - t[reg["brows"], 1].mean()) / cm  # cm above the brows
        above = sm(falloff(d_brow, 5.0)) * np.clip(Y / 1.2, 0, 1) ** 2 * (3 - 2 * np.clip(Y / 1.2, 0, 1))
        ramp = np.clip((Y - 0.6) / 0.8, 0, 1)
        wrinkle = (0.05 * np.sin(2 * np.pi * (Y - 0.6) / 1.1) * falloff(d_brow, 4.5) * ramp * ramp
                   * (3 - 2 * ramp))
        off["brow_raise"] = field(dy=0.6 * np.maximum(w_brow, 0.75 * above), dz=wrinkle)
        Xe = t[:, 0] / cm
        inner = np.clip(1.3 - np.abs(Xe) / 4.0, 0.3, 1.0)
        off["brow_frown"] = field(dx=-0.35 * np.tanh(Xe / 0.8) * inner * w_brow, dy=-0.45 * w_brow * inner,
                                  dz=0.1 * w_brow)
        d_corner = dist(np.array([mu[0], mu[-1], ml[0], ml[-1]]))
        w_corner = sm(falloff(d_corner, 2.6))
        cheeks = reg["cheeks"]
        centres = [cheeks[np.argmin(np.linalg.norm(t[cheeks] - t[cheeks[side]].mean(0), axis=1))]
                   for side in (t[cheeks, 0] > 0, t[cheeks, 0] < 0)]
        d_cheek = dist(np.array(centres))
        w_cheek = sm(falloff(d_cheek, 3.2))
        lids_lo = np.concatenate([reg["left_lower_lid_margin"], reg["right_lower_lid_margin"]])
        lids_up = np.concatenate([reg["left_upper_lid_margin"], reg["right_upper_lid_margin"]])
        d_lid_up, src_lid_up = dist(lids_up, True)
        d_lid_lo, src_lid_lo = dist(lids_lo, True)
        lower_lid = d_lid_lo < d_lid_up
        w_squint = sm(falloff(d_lid_lo, 0.9) * lower_lid)
        off["cheek_raise"] = field(dx=0.4 * np.tanh(X / 1.0) * w_corner, dy=0.45 * w_corner + 0.3 * w_cheek
                                   + 0.12 * w_squint, dz=-0.12 * w_corner + 0.25 * w_cheek)
        self.mouth_centre, self.mouth_half = mouth_centre, half  # half: cm
        self.fields = {"mouth_x": X, "upper_side": upper_side, "d_up": d_up, "d_lo": d_lo, "d_m": d_m,
                       "lat": lat, "near": near, "peri": peri, "w_up": w_up, "w_lo": w_lo, "brow": w_brow,
                       "corner": w_corner, "d_corner": d_corner, "lat_wide": lat_wide, "lower_lip": lower_lip,
                       "cheek": w_cheek, "d_cheek": d_cheek, "squint": w_squint}
        self._linear = [c for c in CHANNELS if c in off]
        self._offsets = (np.stack([off[c] for c in self._linear]).reshape(len(self._linear), -1)
                         .astype(np.float32))
        self._linear_index = np.array([CHANNELS.index(c) for c in self._linear])

        # jaw: rigid rotation of the jaw region, smooth falloff around it
        hinge = reg["jaw_hinge"]
        self.hinge = t[hinge].mean(0)
        # 1 deep inside the jaw region, 1/2 on its border, 0 beyond; the slit is a hard border
        in_jaw = np.zeros(V, bool)
        in_jaw[reg["jaw"]] = True
        free = ~in_jaw & ~((d_up < 0.6) & upper_side)  # not the jaw, not the upper lip at the slit
        ramp = 1.8
        w_jaw = np.where(in_jaw, 0.5 + 0.5 * (1 - falloff(dist(np.nonzero(free)[0]), ramp)),
                         0.5 * falloff(dist(reg["jaw"]), ramp))
        w_jaw = sm(w_jaw, pin=np.concatenate([mu, ml]))
        self.fields["jaw"] = w_jaw
        self._jaw_idx = np.nonzero(w_jaw > 1e-4)[0]
        self._jaw_w = w_jaw[self._jaw_idx]

        # lids: per-column closing angles about each eyeball centre
        def angle(p: np.ndarray, c: np.ndarray) -> np.ndarray:
            return np.arctan2(p[..., 1] - c[..., 1], p[..., 2] - c[..., 2])

        side_of = np.zeros(V, np.int64)
        side_of[reg["right_upper_lid_margin"]] = 1
        side_of[reg["right_lower_lid_margin"]] = 1
        pairs = []
        for s in ("left", "right"):
            pairs.append((reg[f"{s}_upper_lid_margin"], reg[f"{s}_lower_lid_margin"]))
        close_angle = np.zeros(V)
        for up, lo in pairs:
            c = self.eye_centres[side_of[up[0]]]
            a = angle(t[up], c) - angle(t[lo], c)
            close_angle[up] = a
            close_angle[lo] = a
        lid_margins = np.concatenate([lids_up, lids_lo])
        w_lid_up = sm(falloff(d_lid_up, 1.0) * ~lower_lid, pin=lid_margins)
        w_lid_lo = sm(falloff(d_lid_lo, 0.6) * lower_lid, pin=lid_margins)
        src = np.where(lower_lid, src_lid_lo, src_lid_up)
        lid_idx = np.nonzero(((w_lid_up > 1e-4) & ~lower_lid) | ((w_lid_lo > 1e-4) & lower_lid))[0]
        self.lid_idx = lid_idx
        self.lid_upper = ~lower_lid[lid_idx]
        self.lid_w = np.where(self.lid_upper, w_lid_up[lid_idx], w_lid_lo[lid_idx])
        self.lid_alpha = close_angle[src[lid_idx]]
        self.lid_centre = self.eye_centres[side_of[src[lid_idx]]]

        # lip seal: every lip vertex follows its nearest margin vertex towards the meeting line
        seal_w = sm(falloff(d_m, 1.1), pin=np.concatenate([mu, ml]))
        seal_idx = np.nonzero(seal_w > 1e-4)[0]
        self._seal_idx = seal_idx
        self._seal_w = seal_w[seal_idx]
        col_of = np.full(V, -1)
        col_of[mu] = np.arange(len(mu))
        col_of[ml] = np.arange(len(ml))
        src_m = np.where(upper_side, src_up, src_lo)
        self._seal_col = col_of[src_m[seal_idx]]
        self._seal_upper = upper_side[seal_idx]
        self._mu, self._ml = mu, ml

    def distance(self, sources: np.ndarray, sources_out: bool = False):
        """Graph distance (cm) of every vertex from the nearest of `sources`; with `sources_out`, also
        which source is nearest."""
        from scipy.sparse.csgraph import dijkstra  # here: importing scipy.sparse costs 0.3-0.6 s

        d, _, src = dijkstra(self._graph, directed=False, indices=sources, min_only=True,
                             return_predecessors=True)
        return (d / self.cm, src) if sources_out else d / self.cm

    def _build_graph(self):
        """The mesh's edges plus its 2-ring (Euclidean lengths): graph distances close to geodesic ones
        without the diamond-shaped bias of a grid's edges. Also sets the neighbour-average operator."""
        from scipy.sparse import coo_matrix

        f = self.faces
        n = len(self.template)
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        e = np.unique(np.sort(e, 1), axis=0)
        adj = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
        adj = ((adj + adj.T) > 0).astype(np.float64)
        degree = np.asarray(adj.sum(1)).ravel()
        self._average = (adj.multiply(1 / np.maximum(degree, 1)[:, None])).tocsr()
        ring2 = (adj @ adj + adj).tocoo()
        keep = ring2.row < ring2.col
        i, j = ring2.row[keep], ring2.col[keep]
        w = np.linalg.norm(self.template[i] - self.template[j], axis=1) + 1e-12
        return coo_matrix((w, (i, j)), shape=(n, n)).tocsr()

    def smooth(self, w: np.ndarray, iterations: int = 12, pin: np.ndarray | None = None) -> np.ndarray:
        """Average each value with its neighbours' (`iterations` times): removes creases of the
        distance falloffs; `pin` vertices keep their values."""
        out = np.asarray(w, np.float64).copy()
        fixed = None if pin is None else out[pin].copy()
        for _ in range(iterations):
            out = 0.5 * out + 0.5 * (self._average @ out)
            if pin is not None:
                out[pin] = fixed
        return out

    def jaw_turn(self, jaw_open: float = 1.0) -> np.ndarray:
        """The template [V, 3] with the jaw turned as `jaw_open` turns it, the lower lip's own drop left out
        (ARKit's jawOpen is the jaw alone; the lip's part is mouthLowerDown)."""
        pos = self.template.astype(np.float32)[None].copy()
        ang = np.float32(jaw_open * JAW_MAX_ANGLE) * self._jaw_w[None, :].astype(np.float32)
        rotate_x(pos, self._jaw_idx, self.hinge.astype(np.float32), ang)
        return pos[0].astype(np.float64)

    def pose(self, weights: np.ndarray) -> np.ndarray:
        """Vertex positions [T, V, 3] (float32) for channel weights [T, C] in `channels` order."""
        w = np.asarray(weights, np.float32)
        if w.ndim != 2 or w.shape[1] != len(CHANNELS):
            raise FacegenError(f"rig weights must have shape [frames, {len(CHANNELS)}], got {w.shape}")
        T = len(w)
        V = len(self.template)
        ch = {c: w[:, i] for i, c in enumerate(CHANNELS)}
        linear = (w[:, self._linear_index] @ self._offsets).reshape(T, V, 3)
        pos = self.template.astype(np.float32)[None] + linear
        # jaw
        ang = ch["jaw_open"][:, None] * np.float32(JAW_MAX_ANGLE) * self._jaw_w[None, :].astype(np.float32)
        rotate_x(pos, self._jaw_idx, self.hinge.astype(np.float32), ang)
        pos += ch["jaw_open"][:, None, None] * self._lip_drop[None]  # after the turn: straight down, as
        # mouthLowerDown draws it (inside the turn it would tip back, and ARKit's fit read a lip rolled in)
        # lids: blink closes, widen opens (less while blinking), frown narrows a little
        blink = ch["blink"][:, None]
        widen = ch["lid_widen"][:, None] * (1 - blink)
        frown = ch["brow_frown"][:, None] * (1 - blink)
        up = self.lid_upper[None, :]
        theta = np.where(up, blink * 0.85 * self.lid_alpha - widen * 0.2 + frown * 0.05,
                         -blink * 0.15 * self.lid_alpha + widen * 0.07)
        theta = theta * self.lid_w[None, :]
        rotate_x(pos, self.lid_idx, self.lid_centre.astype(np.float32), theta.astype(np.float32))
        # lip seal
        close = ch["lip_close"]
        if np.any(close > 0):
            pu, pl = pos[:, self._mu], pos[:, self._ml]
            target = pu + 0.45 * (pl - pu)
            delta = np.where(self._seal_upper[None, :, None], (target - pu)[:, self._seal_col],
                             (target - pl)[:, self._seal_col])
            pos[:, self._seal_idx] += (close[:, None] * self._seal_w[None, :])[..., None] * delta
        return pos
