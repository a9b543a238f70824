"""The measures of benchmarks/real_faces.py on tracked landmarks: pure numpy, no tracker, no model.

Everything is in cm on the iris scale: the clip's median distance between the two iris centres (MediaPipe's
refine_landmarks points 468 and 473) is 6.3 cm, the adult mean interpupillary distance, which facegen's rig
also uses (facegen.face.rig.EYE_SPACING_CM: the eyeball centres). One scale per clip, not per frame: the iris
points jitter by a pixel or two at GRID's 360 x 288.

* `tracks_of`: per-frame lip aperture (inner-lip midpoints 13-14), mouth width (corners 61-291) and jaw
  opening (nose tip 1 to chin 152, less the clip's 5th percentile: 0 with the jaw up) of landmarks [T, 478];
* `best_lag`, `median_ratio`, `closure_rate`: facegen against the real face in the same tracker;
* `closures`: each p/b/m's closure as the tracker sees it (when the lips close and open, against the phone's
  acoustic start and end);
* `vowel_values`: aperture, jaw and width at the middle of each vowel (a diphthong's two halves apart, as the
  rig's visemes split it: facegen.phonetics.CMU_VISEMES);
* `envelope_lead`, `onset_lead`: how far lip opening runs ahead of the sound.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from facegen.lipsync import lagged_r
from facegen.phonetics import CMU_VISEMES, CMU_VOWELS

IRIS_CM = 6.3  # the iris-centre distance, cm (mean adult interpupillary distance; the rig's eye spacing)
IRIS = (468, 473)  # iris centres (refine_landmarks)
LIP_INNER = (13, 14)  # upper and lower inner-lip midpoints
CORNERS = (61, 291)  # mouth corners
NOSE_CHIN = (1, 152)  # nose tip, chin
OPEN_CM = 0.2  # a speech frame of the real face counts as open above this aperture (lipsync.OPEN_MM: 2 mm)
CLOSED_CM = 0.1  # lips closed below this aperture: the tracker reads closed lips as 0.00-0.05 cm
MAX_LAG_S = 0.2  # best-lag search, either way
BILABIALS = ("P", "B", "M")
# vowel classes for the summary (the rig's vowel visemes; AY/AW/EY/OY count as their two halves)
VOWEL_CLASSES = {
    "open": ("AA", "AE"),
    "mid": ("AH", "EH", "ER"),
    "spread": ("IY", "IH"),
    "rounded": ("AO", "OW", "UH", "UW"),
}


# consonant classes for the jaw at consonants (the rig's consonant visemes, facegen.phonetics)
CONSONANT_CLASSES = {
    "p/b/m": ("P", "B", "M"),
    "f/v": ("F", "V"),
    "th": ("TH", "DH"),
    "s/z/sh": ("S", "Z", "SH", "ZH", "CH", "JH"),
    "t/d/n": ("T", "D", "N"),
    "l": ("L",),
    "k/g": ("K", "G", "NG"),
    "w": ("W",),
}


@dataclass
class Tracks:
    """What the tracker saw of one face, per frame, in cm: `aperture`, `width`, `jaw`; `found` frames with a
    face (the others interpolated), `iris_px` the clip's iris-centre distance in pixels."""

    aperture: np.ndarray
    width: np.ndarray
    jaw: np.ndarray
    found: int
    iris_px: float

    def __len__(self) -> int:
        return len(self.aperture)

    def cut(self, n: int) -> Tracks:
        return Tracks(self.aperture[:n], self.width[:n], self.jaw[:n], min(self.found, n), self.iris_px)


def _fill(x: np.ndarray) -> np.ndarray:
    """x with its NaN entries interpolated from the nearest tracked frames (held at the ends)."""
    ok = np.isfinite(x)
    if ok.all() or not ok.any():
        return x
    k = np.arange(len(x))
    return np.interp(k, k[ok], x[ok])


def _distance(lm: np.ndarray, a: int, b: int) -> np.ndarray:
    return np.linalg.norm(lm[:, a, :2].astype(np.float64) - lm[:, b, :2], axis=1)


def tracks_of(landmarks: np.ndarray) -> Tracks:
    """Tracks of landmarks [T, >=478, 2+] (pixels) (NaN rows: no face found), distances in the image plane."""
    lm = np.asarray(landmarks)
    if lm.ndim != 3 or lm.shape[1] < 478:
        raise ValueError(f"landmarks must be [frames, 478, 2 or 3], got {list(lm.shape)}")
    found = np.isfinite(lm[:, IRIS[0], 0])
    if not found.any():
        raise ValueError("the tracker found no face in any frame")
    iris_px = float(np.median(_distance(lm[found], *IRIS)))
    cm = IRIS_CM / iris_px
    jaw = _fill(_distance(lm, *NOSE_CHIN) * cm)
    return Tracks(
        _fill(_distance(lm, *LIP_INNER) * cm),
        _fill(_distance(lm, *CORNERS) * cm),
        jaw - np.percentile(jaw, 5),
        int(found.sum()),
        iris_px,
    )


# ------------------------------------------------------------------------------------ facegen vs real
def lag_curve(
    pred: np.ndarray, ref: np.ndarray, rate: float, max_lag_s: float = MAX_LAG_S
) -> dict[int, float]:
    """Pearson r of pred[t] against ref[t - lag] for each lag in frames with |lag| <= max_lag_s (lag > 0:
    pred is late); lags where r is undefined are left out."""
    n = round(max_lag_s * rate)
    return {lag: r for lag in range(-n, n + 1) if (r := lagged_r(pred, ref, lag)) is not None}


def best_of(curve: dict[int, float]):
    """(r, lag) of the highest r of a lag curve; (None, None) for an empty one."""
    return max(((r, lag) for lag, r in curve.items()), default=(None, None), key=lambda x: x[0])


def pooled_best(curves: Sequence[dict[int, float]]):
    """(r, lag) of the highest mean r over many clips' lag curves (the lags all of them have): one lag for
    all clips, steadier than the mean of each clip's best lag."""
    common = set.intersection(*(set(c) for c in curves)) if curves else set()
    return best_of({lag: float(np.mean([c[lag] for c in curves])) for lag in common})


def best_lag(pred: np.ndarray, ref: np.ndarray, fps: float, max_lag_s: float = MAX_LAG_S):
    """(r, lag in frames) of the best Pearson r of pred[t] against ref[t - lag] over |lag| <= max_lag_s
    (lag > 0: pred is late); (None, None) when no lag gives an r."""
    return best_of(lag_curve(pred, ref, fps, max_lag_s))


def median_ratio(pred: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float | None:
    """median(pred[mask]) / median(ref[mask]): how wide pred opens where ref is open; None without frames."""
    mask = np.asarray(mask, bool)
    if not mask.any():
        return None
    den = float(np.median(ref[mask]))
    return float(np.median(pred[mask])) / den if den > 0 else None


def closure_rate(
    aperture: np.ndarray, frames: Sequence[int], closed: float = CLOSED_CM, reach: int = 0
) -> float | None:
    """Share of `frames` (p/b/m midpoints) at which the aperture is under `closed`: at the frame itself, or
    anywhere within `reach` frames of it; None without frames (those outside the clip are dropped)."""
    idx = np.asarray(frames, np.int64)
    idx = idx[(idx >= 0) & (idx < len(aperture))]
    if not len(idx):
        return None
    lows = [aperture[max(0, i - reach) : i + reach + 1].min() for i in idx]
    return float(np.mean(np.asarray(lows) < closed))


def speech_span(words: Sequence, num_frames: int, fps: float, pad: float = MAX_LAG_S) -> np.ndarray:
    """Boolean [num_frames]: from the first word's start to the last word's end, `pad` seconds either side."""
    t = np.arange(num_frames) / fps
    spoken = [(float(w[1]), float(w[2])) for w in words]
    if not spoken:
        return np.zeros(num_frames, bool)
    return (t >= spoken[0][0] - pad) & (t <= spoken[-1][1] + pad)


# ------------------------------------------------------------------------------------------ closures
def _crossing(x: np.ndarray, k: int, step: int, level: float) -> float:
    """Sub-frame time (frames) where x crosses `level` between frame k (under it) and k + step (over it);
    the clip's edge when there is no frame k + step."""
    j = k + step
    if j < 0 or j >= len(x):
        return float(k)
    return k + step * (level - x[k]) / (x[j] - x[k])


def closures(aperture: np.ndarray, phones: Sequence, fps: float, closed: float = CLOSED_CM) -> list[dict]:
    """One row per p/b/m phone (CMU phones (name, start, end), seconds): `phone`, `closed` (at its midpoint),
    and when closed: `close_s` / `release_s`, the times the aperture falls under and rises over `closed`
    (linear between frames), `duration_s` their difference, `close_offset_s` = close_s - the phone's start and
    `release_offset_s` = release_s - its end (> 0: the lips move after the acoustic boundary), and `edge`: the
    phone starts or ends its stretch of speech (the closure runs into the rest pose, its duration is not the
    phone's)."""
    rows = []
    names = [str(p[0]).upper().rstrip("012") for p in phones]
    for i, (name, (_, start, end)) in enumerate(zip(names, phones, strict=True)):
        if name not in BILABIALS:
            continue
        start, end = float(start), float(end)
        mid = int(np.clip(round((start + end) / 2 * fps), 0, len(aperture) - 1))
        row = {"phone": name, "start_s": start, "end_s": end, "closed": bool(aperture[mid] < closed)}
        gap_before = start - float(phones[i - 1][2]) if i else np.inf
        gap_after = float(phones[i + 1][1]) - end if i + 1 < len(phones) else np.inf
        row["edge"] = bool(gap_before > 0.05 or gap_after > 0.05)
        if row["closed"]:
            a = b = mid
            while a > 0 and aperture[a - 1] < closed:
                a -= 1
            while b + 1 < len(aperture) and aperture[b + 1] < closed:
                b += 1
            close_s, release_s = (
                _crossing(aperture, a, -1, closed) / fps,
                _crossing(aperture, b, 1, closed) / fps,
            )
            row.update(
                close_s=close_s,
                release_s=release_s,
                duration_s=release_s - close_s,
                close_offset_s=close_s - start,
                release_offset_s=release_s - end,
            )
        rows.append(row)
    return rows


# -------------------------------------------------------------------------------------------- vowels
def _at(x: np.ndarray, t: float, fps: float) -> float:
    return float(np.interp(t * fps, np.arange(len(x)), x))


def rest_width(tr: Tracks, speech: np.ndarray) -> float:
    """The mouth's width at rest: the median over non-speech frames with the lips closed (else over all)."""
    rest = ~np.asarray(speech, bool) & (tr.aperture < CLOSED_CM)
    return float(np.median(tr.width[rest] if rest.sum() >= 3 else tr.width))


def vowel_values(
    tr: Tracks, phones: Sequence, fps: float, width0: float, extra: dict[str, np.ndarray] | None = None
) -> list[dict]:
    """Per vowel viseme occurrence: `viseme`, `phone`, and at its middle `aperture`, `jaw`, `width` and
    `width_change` (width - width0, the rest width), cm, and each series of `extra` under its key. A diphthong
    (AY = AA + IH, ...) gives its halves."""
    rows = []
    for name, start, end in phones:
        name = str(name).upper().rstrip("012")
        if name not in CMU_VOWELS:
            continue
        parts = CMU_VISEMES[name]
        step = (float(end) - float(start)) / len(parts)
        for k, vis in enumerate(parts):
            t = float(start) + (k + 0.5) * step
            w = _at(tr.width, t, fps)
            rows.append(
                {
                    "viseme": vis,
                    "phone": name,
                    "t": t,
                    "aperture": _at(tr.aperture, t, fps),
                    "jaw": _at(tr.jaw, t, fps),
                    "width": w,
                    "width_change": w - width0,
                    **{k: _at(x, t, fps) for k, x in (extra or {}).items()},
                }
            )
    return rows


def vowel_class(viseme: str) -> str | None:
    return next((c for c, members in VOWEL_CLASSES.items() if viseme in members), None)


def summarize_vowels(
    rows: Sequence[dict], keys=("aperture", "aperture_rel", "jaw", "width_change", "geometric",
                                "geometric_width_change")
) -> dict:
    """Per viseme and per class (VOWEL_CLASSES): n and the median of each of `keys` the rows have."""
    keys = [k for k in keys if rows and all(k in r for r in rows)]
    groups: dict[str, list[dict]] = {}
    for row in rows:
        groups.setdefault(row["viseme"], []).append(row)
        if (c := vowel_class(row["viseme"])) is not None:
            groups.setdefault(f"class:{c}", []).append(row)
    return {
        g: {"n": len(rs), **{k: float(np.median([r[k] for r in rs])) for k in keys}}
        for g, rs in sorted(groups.items())
    }


def jaw_at_consonants(clips: Sequence[tuple[np.ndarray, Sequence]], fps: float) -> dict[str, dict]:
    """How far the jaw is open at consonants against vowels: over `clips` ((jaw [T] in cm, phones) pairs),
    the mean jaw at the middle of each CONSONANT_CLASSES phone over the mean at the middle of every vowel
    ({class: {"n", "ratio"}}, with "vowels": {"n", "jaw"} in cm). The tracker's jaw is the clip's nose-to-chin
    distance less its 5th percentile, so a class's ratio says how much of the vowels' opening it keeps."""
    found: dict[str, list[float]] = {}
    for jaw, phones in clips:
        for name, start, end in phones:
            name = str(name).upper().rstrip("012")
            key = "vowels" if name in CMU_VOWELS else next(
                (c for c, members in CONSONANT_CLASSES.items() if name in members), None)
            if key is not None:
                found.setdefault(key, []).append(_at(jaw, (float(start) + float(end)) / 2, fps))
    vowels = float(np.mean(found["vowels"])) if found.get("vowels") else None
    out: dict[str, dict] = {"vowels": {"n": len(found.get("vowels", [])), "jaw": vowels}}
    for c in CONSONANT_CLASSES:
        vals = found.get(c, [])
        out[c] = {"n": len(vals), "ratio": float(np.mean(vals)) / vowels if vals and vowels else None}
    return out


def response_curve(
    tracked: np.ndarray, geometric: np.ndarray, edges=(0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.2)
) -> list[dict]:
    """How the tracker reads facegen's face: per bin of the geometric aperture (cm, `edges`), the frames and
    the median tracked aperture."""
    out = []
    for lo, hi in itertools.pairwise(edges):
        m = (geometric >= lo) & (geometric < hi)
        if m.any():
            out.append(
                {
                    "geometric_cm": [lo, hi],
                    "frames": int(m.sum()),
                    "tracked_median_cm": float(np.median(tracked[m])),
                }
            )
    return out


# ------------------------------------------------------------------------------------------- leads
def envelope_curve(
    aperture: np.ndarray,
    fps: float,
    loudness_db: np.ndarray,
    rate: float = 100.0,
    max_lag_s: float = MAX_LAG_S,
    floor_db: float = 40.0,
) -> dict[int, float]:
    """Lag curve (lag_curve, in 1/`rate` s steps) of the sound's loudness (dB at `rate` Hz, floored `floor_db`
    under its peak) against the aperture interpolated to `rate`: r at lag L pairs the sound at t with the
    lips at t - L, so the best lag > 0 means the lips move before the sound."""
    env = np.maximum(np.asarray(loudness_db, np.float64), float(np.max(loudness_db)) - floor_db)
    t = np.arange(len(env)) / rate
    inside = t <= (len(aperture) - 1) / fps
    ap = np.interp(t[inside] * fps, np.arange(len(aperture)), aperture)
    return lag_curve(env[inside], ap, rate, max_lag_s)


def envelope_lead(
    aperture: np.ndarray,
    fps: float,
    loudness_db: np.ndarray,
    rate: float = 100.0,
    max_lag_s: float = MAX_LAG_S,
):
    """(lead s, r): the best lag of envelope_curve in seconds (> 0: the lips lead the sound)."""
    r, lag = best_of(envelope_curve(aperture, fps, loudness_db, rate, max_lag_s))
    return (None, None) if lag is None else (lag / rate, r)


def onset_lead(
    aperture: np.ndarray,
    words: Sequence,
    phones: Sequence,
    fps: float,
    closed: float = CLOSED_CM,
    window_s: float = 0.6,
) -> float | None:
    """How long before the first word's acoustic start the lips part (s; > 0: before): the aperture's last
    rise over `closed` from the closed lips in the `window_s` before the start. None when the lips are not
    closed there, or the word starts with a bilabial (they part at its release, not the word's start)."""
    if not words or not phones:
        return None
    first = str(phones[0][0]).upper().rstrip("012")
    if first in BILABIALS:
        return None
    start = float(words[0][1])
    lo, hi = (
        max(0, int(np.floor((start - window_s) * fps))),
        min(len(aperture) - 1, int(np.ceil(start * fps))),
    )
    shut = [k for k in range(lo, hi + 1) if aperture[k] < closed]
    if not shut:
        return None
    k = shut[-1]
    while k + 1 < len(aperture) and aperture[k + 1] < closed:  # still closed after the window
        k += 1
    if k + 1 >= len(aperture):
        return None
    return start - _crossing(aperture, k, 1, closed) / fps
