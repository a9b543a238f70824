"""The deformations behind ARKit's 52 blend shapes on facegen's procedural face (a Rig's fields and poses).

`shape_offsets(rig)` returns {ARKit name: offsets [V, 3] float64 at weight 1}. Shapes with a rig channel are
that channel's pose minus the template (jawOpen = jaw_open, mouthFunnel = lip_funnel, eyeBlink = blink, ...);
the others are new deformers built on the rig's falloff fields, distances and lid rotations (mouthLeft,
mouthPress, mouthShrug*, mouthDimple, mouthFrown, noseSneer, cheekPuff, jaw*, eyeSquint, eyeLook*, ...).
Left/Right pairs are one symmetric deformation times a smooth blend across the face's midline (Left = +x,
the character's own left), so Left + Right is the symmetric shape. docs/arkit.md describes every shape.
"""

from __future__ import annotations

import numpy as np

from facegen.face.rig import (
    CHANNELS,
    JAW_MAX_ANGLE,
    LOWER_LIP_FORWARD,
    STRETCH_SPREAD,
    WIDE_SPREAD,
    Rig,
    falloff,
    rotate_x,
)

SIDE_BLEND_CM = 1.0  # the Left/Right weights cross over between -1 cm and +1 cm of the midline
LOOK_SIDE, LOOK_UP, LOOK_DOWN = 0.52, 0.42, 0.45  # eye rotation (rad) at eyeLookIn/Out, Up, Down = 1
EYE_ROTATED_DEG, EYE_FIXED_DEG = 45.0, 85.0  # the eyeball cap turns fully inside, not at all at its rim
SMILE_GAIN = 1.35  # mouthSmile = the rig's smile (the mouth-corner part of cheek_raise) times this
PUFF_AXIS_CM = 4.0  # cheekPuff pushes away from a vertical axis this far behind the eyeball centres
# ARKit's jawOpen 1 is the mouth opened as wide as it goes (Apple's reference pose): the jaw turned by
# JAW_OPEN_ANGLE, about 4 cm between the lips (adults open 40-60 mm between the incisors; against a real
# capture facegen's jawOpen range was 1.86x the iPhone's; docs/arkit_capture.md).
# jawOpen is the jaw's turn alone (the lower lip's own drop, LIP_DROP_CM, is mouthLowerDown, as on an
# iPhone), linear as every blend shape is; mouthClose is the lips shut against that jaw.
JAW_OPEN_ANGLE = 0.66  # rad
JAW_OPEN_SCALE = JAW_OPEN_ANGLE / JAW_MAX_ANGLE  # jawOpen 1 is this many of the rig's jaw turns (2.42)


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _rotation(axis: str, angle: float) -> np.ndarray:
    """3 x 3 rotation about the x or y axis (right-handed)."""
    c, s = np.cos(angle), np.sin(angle)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


class _Deformers:
    """The rig's template, scale and fields, and the operations every shape is made of."""

    def __init__(self, rig: Rig, regions: dict[str, np.ndarray]) -> None:
        self.rig = rig
        self.t = rig.template
        self.cm = rig.cm
        self.f = rig.fields
        self.regions = regions
        self.rest = rig.pose(np.zeros((1, len(CHANNELS)), np.float32))[0].astype(np.float64)
        x = (self.t[:, 0] - rig.mouth_centre[0]) / self.cm  # cm from the midline
        self.x = x
        self.left = _smoothstep((x / SIDE_BLEND_CM + 1) / 2)
        self.right = 1.0 - self.left

    def pose(self, **channels: float) -> np.ndarray:
        w = np.zeros((1, len(CHANNELS)), np.float32)
        for name, value in channels.items():
            w[0, CHANNELS.index(name)] = value
        return self.rig.pose(w)[0].astype(np.float64)

    def delta(self, **channels: float) -> np.ndarray:
        """A rig pose minus the template."""
        return self.pose(**channels) - self.rest

    def vec(self, dx=0.0, dy=0.0, dz=0.0) -> np.ndarray:
        """Offsets [V, 3] from components in cm (scalars or per-vertex arrays)."""
        n = len(self.t)
        return np.stack([np.broadcast_to(d, (n,)) for d in (dx, dy, dz)], 1) * self.cm

    def field(self, d: np.ndarray, radius: float, mask: np.ndarray | bool = True) -> np.ndarray:
        """A smooth weight: 1 at distance 0 (cm), 0 from `radius` on, only where `mask`."""
        return self.rig.smooth(falloff(d, radius) * mask)

    def nearest_pair(self, candidates: np.ndarray, dx: float, dy: float) -> np.ndarray:
        """Two vertices of `candidates`: the one nearest (in x, y) to the point dx, dy cm from the mouth
        centre (dx > 0: on the left), and the one nearest to its mirror image (the same on a symmetric
        face)."""
        def nearest(target: np.ndarray) -> int:
            return int(candidates[np.argmin(np.linalg.norm(self.t[candidates, :2] - target, axis=1))])

        left = nearest(self.rig.mouth_centre[:2] + np.array([dx, dy]) * self.cm)
        mirrored = self.t[left, :2].copy()
        mirrored[0] = 2 * self.rig.mouth_centre[0] - mirrored[0]
        return np.array([left, nearest(mirrored)])

    def lids(self, upper: np.ndarray | float, lower: np.ndarray | float) -> np.ndarray:
        """Offsets of turning the lids about the eyeball centres: `upper` / `lower` rad per lid column
        (positive: down), faded with the rig's lid weights."""
        r = self.rig
        pos = self.rest.astype(np.float32)[None].copy()
        theta = np.where(r.lid_upper, upper, lower) * r.lid_w
        rotate_x(pos, r.lid_idx, r.lid_centre.astype(np.float32), theta[None].astype(np.float32))
        return pos[0].astype(np.float64) - self.rest

    def eyeball(self, side: int, rotation: np.ndarray) -> np.ndarray:
        """Offsets of turning eyeball `side` (0 left, 1 right): its points slide over the eyeball's
        ellipsoid, the front cap by `rotation`, fading to none at the cap's rim (no gap opens)."""
        idx = self.regions[("left_eyeball", "right_eyeball")[side]]
        c, axes = self.rig.eye_centres[side], self.rig.eye_axes[side]
        u = (self.t[idx] - c) / axes
        polar = np.degrees(np.arccos(np.clip(u[:, 2] / np.linalg.norm(u, axis=1), -1, 1)))
        g = 1 - _smoothstep((polar - EYE_ROTATED_DEG) / (EYE_FIXED_DEG - EYE_ROTATED_DEG))
        turned = u @ rotation.T
        # the same rotation by a fraction g of the angle: interpolate on the sphere and renormalise
        mixed = u + g[:, None] * (turned - u)
        mixed *= (np.linalg.norm(u, axis=1) / np.maximum(np.linalg.norm(mixed, axis=1), 1e-12))[:, None]
        out = np.zeros_like(self.t)
        out[idx] = c + mixed * axes - self.t[idx]
        return out

    def sided(self, out: dict[str, np.ndarray], name: str, offsets: np.ndarray) -> None:
        """`name`Left and `name`Right: the symmetric `offsets` times the midline blend."""
        out[name + "Left"] = offsets * self.left[:, None]
        out[name + "Right"] = offsets * self.right[:, None]


def _eyes(d: _Deformers, out: dict[str, np.ndarray]) -> None:
    r = d.rig
    d.sided(out, "eyeBlink", d.delta(blink=1.0))
    d.sided(out, "eyeWide", d.delta(lid_widen=1.0))
    alpha = r.lid_alpha
    d.sided(out, "eyeSquint", d.lids(0.12 * alpha, -0.4 * alpha) + d.vec(dy=0.12 * d.f["squint"]))
    lid_up, lid_down = d.lids(-0.16, -0.05), d.lids(0.3 * alpha, 0.07)
    for side, (name, sign) in enumerate((("Left", 1.0), ("Right", -1.0))):
        mask = (d.left if side == 0 else d.right)[:, None]
        out[f"eyeLookUp{name}"] = d.eyeball(side, _rotation("x", -LOOK_UP)) + lid_up * mask
        out[f"eyeLookDown{name}"] = d.eyeball(side, _rotation("x", LOOK_DOWN)) + lid_down * mask
        # in: towards the nose (-x for the left eye); a rotation about +y by +a turns the gaze to +x
        out[f"eyeLookIn{name}"] = d.eyeball(side, _rotation("y", -sign * LOOK_SIDE))
        out[f"eyeLookOut{name}"] = d.eyeball(side, _rotation("y", sign * LOOK_SIDE))


def _jaw(d: _Deformers, out: dict[str, np.ndarray]) -> None:
    jaw = d.f["jaw"]
    out["jawOpen"] = JAW_OPEN_SCALE * (d.rig.jaw_turn(1.0) - d.rest)
    out["jawForward"] = d.vec(dy=-0.08 * jaw, dz=0.6 * jaw)
    out["jawLeft"] = d.vec(dx=0.65 * jaw)
    out["jawRight"] = d.vec(dx=-0.65 * jaw)
    # ARKit's mouthClose: the lips closed against an open jaw
    out["mouthClose"] = JAW_OPEN_SCALE * (d.pose(jaw_open=1.0, lip_close=1.0) - d.rig.jaw_turn(1.0))
    # no tongue on this face: the small jaw drop and the lips parting a tongue pushed out would cause
    w_lo = d.field(d.f["d_lo"], 2.0, ~d.f["upper_side"])
    # no tongue on this face: the lower lip pushed out and down as a tongue over it would (no jaw: that is
    # jawOpen)
    out["tongueOut"] = d.vec(dy=-0.2 * w_lo * d.f["lat"], dz=0.45 * w_lo * d.f["lat"])


def _mouth(d: _Deformers, out: dict[str, np.ndarray]) -> None:
    f = d.f
    X, corner, near, lat = f["mouth_x"], f["corner"], f["near"], f["lat"]
    upper = f["upper_side"]
    sgn = np.where(upper, 1.0, -1.0)
    w_lo = f["w_lo"]
    out["mouthFunnel"] = d.delta(lip_funnel=1.0)
    # ARKit's pucker is the closed lips contracted and pushed forward (a kiss): the rig's rounding alone parts
    # them 4 mm, and a pursed W or /u/ (facegen.synth.curves.ROUND_CLOSE) would read as mouthClose
    out["mouthPucker"] = d.delta(lip_round=1.0, lip_close=1.0)
    out["mouthRollLower"] = d.delta(lower_lip_tuck=1.0)
    # the upper lip's margin curls in over the teeth (down and back), the skin above it hardly moves
    out["mouthRollUpper"] = d.vec(dy=-0.25 * near * upper * lat - 0.05 * w_lo * lat,
                                  dz=-0.4 * near * upper * lat)
    wide = d.field(f["d_m"], 3.2)
    out["mouthLeft"] = d.vec(dx=0.8 * wide, dz=-0.1 * wide * np.tanh(X / 1.5))
    out["mouthRight"] = d.vec(dx=-0.8 * wide, dz=0.1 * wide * np.tanh(X / 1.5))
    smile = d.vec(dx=0.4 * np.tanh(X / 1.0) * corner, dy=0.45 * corner, dz=-0.12 * corner)  # the rig's
    d.sided(out, "mouthSmile", SMILE_GAIN * smile)
    d.sided(out, "cheekSquint", d.delta(cheek_raise=1.0) - smile)
    d.sided(out, "mouthFrown", d.vec(dx=0.1 * np.tanh(X) * corner, dy=-0.45 * corner, dz=-0.05 * corner))
    d.sided(out, "mouthDimple", d.vec(dx=0.15 * np.tanh(X) * corner, dy=0.05 * corner, dz=-0.35 * corner))
    # the full stretch, of which speech's spreading is a part (rig.STRETCH_SPREAD): 1.1 cm wider at 1
    d.sided(out, "mouthStretch", d.delta(lip_wide=1.0) * (STRETCH_SPREAD / WIDE_SPREAD))
    lat_wide = f["lat_wide"]
    shrug = d.field(f["d_lo"], 2.6, ~upper) * lat_wide
    out["mouthShrugLower"] = d.vec(dy=0.28 * shrug, dz=0.2 * shrug)
    # the whole upper lip pushed out and up (not the reverse of mouthRollUpper: that one is the margin alone)
    shrug_up = d.field(f["d_up"], 2.6, upper) * lat_wide
    out["mouthShrugUpper"] = d.vec(dy=0.1 * shrug_up, dz=0.28 * shrug_up)
    press = d.delta(lip_close=1.0) + d.vec(dy=-0.08 * sgn * near * lat, dz=-0.1 * near)
    d.sided(out, "mouthPress", press)
    lower = f["lower_lip"]  # the rig's own: jaw_open draws the lower lip down the same way
    d.sided(out, "mouthLowerDown", d.vec(dy=-0.55 * lower, dz=0.55 * LOWER_LIP_FORWARD * lower))
    d.sided(out, "mouthUpperUp", d.delta(upper_lip_raise=1.0))


def _upper_face(d: _Deformers, out: dict[str, np.ndarray]) -> None:
    d.sided(out, "browDown", d.delta(brow_frown=1.0))
    raise_ = d.delta(brow_raise=1.0)
    inner = 1 - _smoothstep((np.abs(d.x) - 1.5) / 2.5)  # 1 within 1.5 cm of the midline, 0 beyond 4 cm
    out["browInnerUp"] = raise_ * inner[:, None]
    d.sided(out, "browOuterUp", raise_ * (1 - inner)[:, None])
    # noseSneer: the alae and the skin beside the nose up, the upper lip a little with them
    nose = d.regions["nose"]
    ala = d.field(d.rig.distance(d.nearest_pair(nose, 1.2, 2.85)), 1.6)
    d.sided(out, "noseSneer", d.vec(dx=-0.05 * np.tanh(d.x / 0.5) * ala, dy=0.3 * ala + 0.06 * d.f["w_up"],
                                    dz=0.05 * ala))
    # cheekPuff: the cheeks between the mouth corners and the cheekbones blown outwards, away from a
    # vertical axis PUFF_AXIS_CM behind the eyeballs' centres
    skin = np.nonzero(np.isfinite(d.f["d_m"]))[0]
    puff = d.field(d.rig.distance(d.nearest_pair(skin, 3.2, 1.2)), 3.2)
    axis_z = d.rig.eye_centres[:, 2].mean() - PUFF_AXIS_CM * d.cm
    outwards = np.stack([d.t[:, 0] - d.rig.mouth_centre[0], np.zeros(len(d.t)), d.t[:, 2] - axis_z], 1)
    outwards /= np.maximum(np.linalg.norm(outwards, axis=1), 1e-12)[:, None]
    out["cheekPuff"] = 0.6 * d.cm * puff[:, None] * outwards + d.vec(dz=0.1 * d.f["near"])


def jaw_arc(rig: Rig) -> np.ndarray:
    """The bulge [V, 3] of the rig's jaw turn off jawOpen's straight line, at its widest (jaw_open 1/2): the
    jaw turned half way minus the mean of the template and the full turn. The rig's jaw is a rotation and
    jawOpen a blend shape, linear as every one is, so a half-open jaw lies up to 1 mm off jawOpen's line
    (about 4 j (1 - j) times this at jaw_open j). The ARKit fit solves for it and drops it (`Shapes.hidden`):
    without it the fit made the bulge up out of other shapes, jaw_open 1/2 read as jawForward 0.19,
    mouthShrugLower 0.18 and mouthRollLower 0.14 beside jawOpen 0.22 and mouthLowerDown 0.39."""
    return rig.jaw_turn(0.5) - 0.5 * (rig.jaw_turn(0.0) + rig.jaw_turn(1.0))


def shape_offsets(rig: Rig, regions: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """{ARKit name: offsets [V, 3] float64 at weight 1} for the face `rig` was built on (its `regions`)."""
    d = _Deformers(rig, regions)
    out: dict[str, np.ndarray] = {}
    for part in (_eyes, _jaw, _mouth, _upper_face):
        part(d, out)
    return out
