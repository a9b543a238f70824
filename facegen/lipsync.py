"""Lip-sync metrics: how well a face animation follows speech, measured against a reference animation.

Everything is measured on the procedural face's regions (facegen.face.procedural) in physical units: 1 cm is
the distance between the eyeball centres / 6.3, as the rig (facegen.face.rig) measures it.

* lip aperture: the gap between the upper and lower mouth margin over the middle third of the mouth;
* `lipsync_metrics`: aperture correlation (lag 0 and best lag), aperture ratio, crossed lips, bilabial
  closure, stillness outside speech and upper-face motion of a predicted animation against a reference;
* the reference for any recording (facegen's rig driven by its phone timings) comes from
  facegen.synth.reference.rig_reference;
* `upper_face_response`: the upper-face motion of emotional words relative to neutral words.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from facegen.errors import FacegenError
from facegen.face.mesh import Mesh
from facegen.face.regions import LIPS, LIPSYNC_REGIONS, UPPER_FACE, mouth_middle
from facegen.phonetics import check_alphabet, is_silence, phone_visemes

MAX_LAG = 3  # frames searched either way for the best-lag aperture correlation
OPEN_MM = 2.0  # reference aperture above which a frame counts as open (the face's rest gap is ~1 mm)
CROSSED_MM = -0.5  # aperture below which the lips are crossed
CLOSED_MM = 1.0  # aperture below which the lips are closed
STILL_MM = 1e-3  # upper-face motion below this is none (float32 rounding of the template is ~1e-7 mm)
SPEECH_PAD = 0.1  # s, added to each side of a word or phone by speech_mask

# the targets of issue 10 (on a held-out synthesiser and on recorded human speech): key -> (low, high)
TARGETS: dict[str, tuple[float | None, float | None]] = {
    "aperture_r": (0.70, None),
    "aperture_median_ratio": (0.8, 1.25),
    "crossed_lips_rate": (None, 0.01),
    "bilabial_closure_rate": (0.70, None),
    "rest_aperture_mm": (None, 1.5),
    "upper_face_response": (1.5, None),
}


@dataclass(frozen=True)
class FaceGeometry:
    """What the metrics need from a face, computed once: `upper`/`lower` are the facing margin vertices
    of the middle third of the mouth (the k-th upper faces the k-th lower), `margins` all the mouth's margin
    vertices (its corners among them), `cm` mesh units per cm."""

    template: np.ndarray  # [V, 3] float64
    upper: np.ndarray
    lower: np.ndarray
    cm: float
    lips: np.ndarray
    upper_face: np.ndarray
    margins: np.ndarray

    @classmethod
    def of(cls, mesh: Mesh | FaceGeometry) -> FaceGeometry:
        """The geometry of `mesh` (a FaceGeometry is returned as is); refuses a face without
        LIPSYNC_REGIONS."""
        if isinstance(mesh, FaceGeometry):
            return mesh
        from facegen.face.rig import face_scale

        missing = [r for r in LIPSYNC_REGIONS if r not in mesh.regions]
        if missing:
            raise FacegenError(f"the mesh lacks the lip-sync regions {', '.join(missing)}: use the "
                               "procedural face (facegen.face.template.load_template) or a bundle made on it")
        reg = {k: np.asarray(mesh.regions[k], np.int64) for k in LIPSYNC_REGIONS}
        upper, lower = mouth_middle(reg)
        t = np.asarray(mesh.vertices, np.float64)
        _, cm = face_scale(t, reg)
        margins = np.concatenate([reg["mouth_upper_margin"], reg["mouth_lower_margin"]])
        return cls(template=t, upper=upper, lower=lower, cm=cm, lips=reg[LIPS], upper_face=reg[UPPER_FACE],
                   margins=margins)


def _frames(vertices: np.ndarray, geo: FaceGeometry, what: str) -> np.ndarray:
    v = np.asarray(vertices)
    if v.ndim != 3 or v.shape[1:] != geo.template.shape:
        raise FacegenError(f"{what} must have shape [frames, {len(geo.template)}, 3] (the face's vertices), "
                           f"got {list(v.shape)}")
    return v


def aperture(vertices: np.ndarray, mesh: Mesh | FaceGeometry) -> np.ndarray:
    """Lip aperture [T] in cm of vertices [T, V, 3]: the mean of upper.y - lower.y over the facing margin
    pairs k with n//3 <= k < n - n//3 (n pairs across the mouth); negative: the lips cross."""
    geo = FaceGeometry.of(mesh)
    v = _frames(vertices, geo, "the vertices")
    gap = v[:, geo.upper, 1].astype(np.float64) - v[:, geo.lower, 1].astype(np.float64)
    return gap.mean(1) / geo.cm


def mouth_width(vertices: np.ndarray, mesh: Mesh | FaceGeometry) -> np.ndarray:
    """Mouth width [T] in cm of vertices [T, V, 3]: across the face (x) from the mouth margins' leftmost
    vertex to their rightmost (corner to corner), as a face tracker reads it from the front."""
    geo = FaceGeometry.of(mesh)
    x = _frames(vertices, geo, "the vertices")[:, geo.margins, 0].astype(np.float64)
    return (x.max(1) - x.min(1)) / geo.cm


# ------------------------------------------------------------------------------------------- timings
def _timing(item) -> tuple[str, float, float]:
    """(name, start, end) of a phone or word: an object with .text/.start/.end or a tuple (name, start,
    end)."""
    if hasattr(item, "text"):
        return str(item.text), float(item.start), float(item.end)
    return str(item[0]), float(item[1]), float(item[2])


def speech_mask(items: Sequence, num_frames: int, fps: float, pad: float = SPEECH_PAD) -> np.ndarray:
    """Boolean [num_frames]: frame k (at time k / fps) lies within `pad` seconds of a spoken word or phone.

    `items` are words or phones (objects with .text/.start/.end or tuples (text, start, end), seconds);
    pauses and fillers (names starting with _ + < [, or SIL) are not speech. An item shorter than a
    frame still marks its nearest frame. The pad keeps the mouth's coarticulated approach to and return
    from rest out of the non-speech frames."""
    mask = np.zeros(max(int(num_frames), 0), bool)
    if len(mask) == 0:
        return mask
    for item in items:
        name, start, end = _timing(item)
        if is_silence(name.strip()) or end < start:
            continue
        lo, hi = int(np.ceil((start - pad) * fps - 1e-9)), int(np.floor((end + pad) * fps + 1e-9))
        if hi < lo:
            lo = hi = round((start + end) / 2 * fps)
        mask[np.clip(lo, 0, len(mask) - 1):np.clip(hi, -1, len(mask) - 1) + 1] = True
    return mask


def bilabial_midpoints(phones: Sequence, fps: float, alphabet: str = "espeak") -> np.ndarray:
    """Frame indices (int64) of the midpoints of the p, b and m phones (the rig's PBM viseme in `alphabet`,
    "espeak" or "cmu"): round((start + end) / 2 · fps), the frame the rig closes the lips on even for a
    bilabial shorter than a frame."""
    check_alphabet(alphabet)
    out = []
    for phone in phones:
        name, start, end = _timing(phone)
        if end > start and phone_visemes(name, alphabet) == ("PBM",):
            out.append(round((start + end) / 2 * fps))
    return np.asarray(out, np.int64)


# ------------------------------------------------------------------------------------------- metrics
def _pearson(a: np.ndarray, b: np.ndarray) -> float | None:
    """Pearson r, None when either series is constant or shorter than 3."""
    if len(a) < 3:
        return None
    a, b = a - a.mean(), b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 1e-12 else None


def lagged_r(pred: np.ndarray, ref: np.ndarray, lag: int) -> float | None:
    """Pearson r of pred[t] against ref[t - lag] over the frames both cover (lag > 0: pred is late)."""
    n = min(len(pred), len(ref))
    if lag >= 0:
        return _pearson(pred[lag:n], ref[:n - lag])
    return _pearson(pred[:n + lag], ref[-lag:n])


def _upper_face(vertices: np.ndarray, geo: FaceGeometry, rms: bool = False, chunk: int = 256,
                rest_pose: np.ndarray | None = None) -> np.ndarray:
    """Per frame [T], in mm: the mean (or RMS) displacement of the upper-face vertices from the rest pose (the
    geometry's template unless `rest_pose` [V, 3] is given: a speaker's own neutral face), `chunk` frames at a
    time (long animations stay within memory)."""
    rest = (geo.template if rest_pose is None else np.asarray(rest_pose))[geo.upper_face].astype(np.float32)
    out = []
    for i in range(0, len(vertices), chunk):
        d = np.linalg.norm(vertices[i:i + chunk, geo.upper_face] - rest, axis=2).astype(np.float64)
        out.append(np.sqrt((d * d).mean(1)) if rms else d.mean(1))
    return np.concatenate(out or [np.zeros(0)]) / geo.cm * 10


def _mean(x: np.ndarray) -> float | None:
    return float(x.mean()) if len(x) else None


def _ratio(num: float | None, den: float | None) -> float | None:
    return None if num is None or den is None or den < STILL_MM else num / den


def lipsync_metrics(pred_vertices: np.ndarray, ref_vertices: np.ndarray, mesh: Mesh | FaceGeometry,
                    fps: float, *, speech: np.ndarray | None = None, bilabials: Sequence[int] | None = None,
                    emotional: np.ndarray | None = None, rest_pose: np.ndarray | None = None) -> dict:
    """Lip-sync measures of an animation `pred_vertices` [T, V, 3] against `ref_vertices` [T, V, 3].

    `speech`: boolean [T] mask of speech frames (speech_mask); without it every frame counts as speech
    and the stillness and speech/non-speech measures are None. `bilabials`: frame indices of the p/b/m
    midpoints (bilabial_midpoints; frames outside [0, T) are dropped). `emotional`: the same audio
    animated with emotional words instead of `pred`'s neutral ones, for `upper_face_response`. `rest_pose`:
    the neutral face [V, 3] the animations move from, when it is not the mesh's template (a speaker's face).

    Keys (None where a measure is undefined: no such frames, or a constant series):
      frames; aperture_r: Pearson r of pred and ref aperture at lag 0; aperture_best_r and
      aperture_best_lag: the best r over lags -MAX_LAG..MAX_LAG frames (lagged_r; lag > 0: pred is late);
      open_frames: speech frames with ref aperture > OPEN_MM; aperture_median_ratio and
      aperture_p95_ratio: median (95th percentile) of pred aperture over the open frames divided by that
      of ref over the same frames; aperture_median_mm, ref_aperture_median_mm: those medians;
      crossed_lips_rate: share of all frames with pred aperture < CROSSED_MM;
      bilabials, bilabial_closure_rate: share of the bilabial midpoints with pred aperture < CLOSED_MM,
      bilabial_aperture_mm: mean pred aperture there, ref_bilabial_closure_rate / ref_bilabial_aperture_mm
      the same of ref; rest_aperture_mm: median pred aperture over non-speech frames; rest_motion_mm: mean
      over consecutive non-speech frame pairs of the mean lip-vertex displacement between them;
      upper_face_speech_mm / upper_face_rest_mm: mean displacement of the upper-face vertices from the
      template over speech / non-speech frames, upper_face_speech_ratio = speech / non-speech (None
      when the upper face is still outside speech, < STILL_MM);
      upper_face_response (with `emotional`).
    """
    geo = FaceGeometry.of(mesh)
    pred = _frames(pred_vertices, geo, "the predicted vertices")
    ref = _frames(ref_vertices, geo, "the reference vertices")
    T = len(pred)
    if len(ref) != T:
        raise FacegenError(f"the prediction has {T} frames but the reference {len(ref)}: animate the same "
                           "audio at the same fps")
    speech_given = speech is not None
    speech = np.ones(T, bool) if speech is None else np.asarray(speech, bool)
    if speech.shape != (T,):
        raise FacegenError(f"the speech mask must have {T} entries, got {speech.shape}")
    ap, ap_ref = aperture(pred, geo) * 10, aperture(ref, geo) * 10  # mm

    out: dict = {"frames": T, "aperture_r": lagged_r(ap, ap_ref, 0)}
    lags = [(r, lag) for lag in range(-MAX_LAG, MAX_LAG + 1) if (r := lagged_r(ap, ap_ref, lag)) is not None]
    best = max(lags, default=(None, None), key=lambda x: x[0])
    out["aperture_best_r"], out["aperture_best_lag"] = best

    is_open = speech & (ap_ref > OPEN_MM)
    out["open_frames"] = int(is_open.sum())
    if is_open.any():
        med, med_ref = float(np.median(ap[is_open])), float(np.median(ap_ref[is_open]))
        out["aperture_median_ratio"] = med / med_ref
        out["aperture_p95_ratio"] = float(np.percentile(ap[is_open], 95) / np.percentile(ap_ref[is_open], 95))
        out["aperture_median_mm"], out["ref_aperture_median_mm"] = med, med_ref
    else:
        out.update(dict.fromkeys(("aperture_median_ratio", "aperture_p95_ratio", "aperture_median_mm",
                                  "ref_aperture_median_mm")))
    out["crossed_lips_rate"] = float((ap < CROSSED_MM).mean()) if T else None

    mid = np.asarray([] if bilabials is None else bilabials, np.int64)
    mid = mid[(mid >= 0) & (mid < T)]
    out["bilabials"] = len(mid)
    for prefix, a in (("", ap), ("ref_", ap_ref)):
        out[f"{prefix}bilabial_closure_rate"] = _mean((a[mid] < CLOSED_MM).astype(float))
        out[f"{prefix}bilabial_aperture_mm"] = _mean(a[mid])

    rest = ~speech
    upper = _upper_face(pred, geo, rest_pose=rest_pose)
    out["upper_face_speech_mm"] = _mean(upper[speech])
    if speech_given:
        out["rest_aperture_mm"] = float(np.median(ap[rest])) if rest.any() else None
        still = rest[1:] & rest[:-1]
        step = np.linalg.norm(np.diff(pred[:, geo.lips].astype(np.float64), axis=0), axis=2).mean(1)
        out["rest_motion_mm"] = _mean(step[still] / geo.cm * 10)
        out["upper_face_rest_mm"] = _mean(upper[rest])
        out["upper_face_speech_ratio"] = _ratio(out["upper_face_speech_mm"], out["upper_face_rest_mm"])
    else:
        out.update(dict.fromkeys(("rest_aperture_mm", "rest_motion_mm", "upper_face_rest_mm",
                                  "upper_face_speech_ratio")))
    out["upper_face_response"] = (None if emotional is None
                                  else upper_face_response(pred, emotional, geo, rest_pose=rest_pose))
    return out


_COUNTS = ("frames", "open_frames", "bilabials")
_BY_BILABIALS = ("bilabial_closure_rate", "bilabial_aperture_mm", "ref_bilabial_closure_rate",
                 "ref_bilabial_aperture_mm")


def pool_lipsync(rows: Sequence[dict]) -> dict:
    """The metrics of many sequences as one: counts summed; the bilabial measures weighted by each sequence's
    bilabials, the others by its frames (sequences where a measure is undefined are left out of its mean)."""
    out: dict = {k: int(sum(r.get(k) or 0 for r in rows)) for k in _COUNTS}
    keys = [k for k in (rows[0] if rows else {}) if k not in _COUNTS]
    for key in keys:
        weight = "bilabials" if key in _BY_BILABIALS else "frames"
        pairs = [(r[key], r.get(weight) or 0) for r in rows if r.get(key) is not None]
        total = sum(w for _, w in pairs)
        out[key] = float(sum(v * w for v, w in pairs) / total) if total else None
    if out.get("aperture_best_lag") is not None:
        out["aperture_best_lag"] = round(out["aperture_best_lag"])
    return out


def upper_face_response(neutral_vertices: np.ndarray, emotional_vertices: np.ndarray,
                        mesh: Mesh | FaceGeometry, rest_pose: np.ndarray | None = None) -> float:
    """How much more the upper face moves for emotional words than for neutral words on the same audio:
    the ratio (emotional / neutral) of the mean over frames of the RMS displacement of the upper-face
    vertices from the rest pose (the template, or `rest_pose`: the speaker's own neutral face); inf when only
    the neutral face is still, 1 when both are (< STILL_MM)."""
    geo = FaceGeometry.of(mesh)
    neutral = _mean(_upper_face(_frames(neutral_vertices, geo, "the neutral vertices"), geo, rms=True,
                                rest_pose=rest_pose)) or 0.0
    emotional = _mean(_upper_face(_frames(emotional_vertices, geo, "the emotional vertices"), geo, rms=True,
                                  rest_pose=rest_pose)) or 0.0
    if neutral < STILL_MM:
        return 1.0 if emotional < STILL_MM else float("inf")
    return emotional / neutral


# -------------------------------------------------------------------------------------------- report
_ROWS = (  # key, label, format
    ("aperture_r", "aperture r, lag 0", "{:.3f}"),
    ("aperture_best_r", "aperture r, best lag", "{:.3f}"),
    ("aperture_best_lag", "best lag (frames, + = late)", "{:+d}"),
    ("aperture_median_ratio", "aperture median ratio", "{:.2f}"),
    ("aperture_p95_ratio", "aperture p95 ratio", "{:.2f}"),
    ("aperture_median_mm", "aperture median, open frames (mm)", "{:.2f}"),
    ("ref_aperture_median_mm", "  reference (mm)", "{:.2f}"),
    ("crossed_lips_rate", "crossed lips (share of frames)", "{:.1%}"),
    ("bilabial_closure_rate", "bilabial closure (p/b/m midpoints)", "{:.0%}"),
    ("bilabial_aperture_mm", "aperture at p/b/m midpoints (mm)", "{:.2f}"),
    ("ref_bilabial_aperture_mm", "  reference (mm)", "{:.2f}"),
    ("rest_aperture_mm", "rest aperture, non-speech (mm)", "{:.2f}"),
    ("rest_motion_mm", "lip motion per frame, non-speech (mm)", "{:.3f}"),
    ("upper_face_speech_mm", "upper face from template, speech (mm)", "{:.2f}"),
    ("upper_face_rest_mm", "upper face from template, non-speech (mm)", "{:.2f}"),
    ("upper_face_speech_ratio", "upper face speech / non-speech", "{:.2f}"),
    ("upper_face_response", "upper face, emotional / neutral words", "{:.2f}"),
)


def _target(key: str) -> str:
    lo, hi = TARGETS.get(key, (None, None))
    show = "{:.0%}".format if key.endswith("_rate") else "{:g}".format
    if lo is not None and hi is not None:
        return f"{show(lo)}-{show(hi)}"
    if lo is not None:
        return f">= {show(lo)}"
    return "" if hi is None else f"< {show(hi)}"


def format_lipsync(metrics: dict) -> str:
    """The metrics of lipsync_metrics as a table (measure, value, target); absent or undefined ones as -."""
    width = max(len(label) for _, label, _ in _ROWS)
    head = f"{'measure':<{width}}  {'value':>8}  target"
    lines = [head, "-" * len(head)]
    for key, label, fmt in _ROWS:
        value = metrics.get(key)
        text = "-" if value is None else fmt.format(value)
        lines.append(f"{label:<{width}}  {text:>8}  {_target(key)}".rstrip())
    lines.append(f"{metrics.get('frames', 0)} frames, {metrics.get('open_frames', 0)} open in speech "
                 f"(reference > {OPEN_MM:g} mm), {metrics.get('bilabials', 0)} bilabials")
    return "\n".join(lines)
