"""The animation curves that drive the rig (facegen.face.rig), from timings and the audio's loudness.

`viseme_curves` (lips and jaw from the phones, with coarticulation and prosody), `expression_curves`
(upper face from emotional words only) and `blink_curves` (random blinks); `motion_curves` all of them.
The upper-face curves never look at the phones: the audio carries no emotion, only the text does.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from facegen.face.rig import EXPRESSIONS, LOWER_CHANNELS, UPPER_CHANNELS
from facegen.phonetics import VOWEL_VISEMES, check_alphabet, phone_stress, phone_visemes
from facegen.synth.lexicon import LEXICON, Emotion, lookup


# ---------------------------------------------------------------------------------------------- style
@dataclass(frozen=True)
class SpeakerStyle:
    """How one synthetic speaker moves."""

    articulation: float = 1.0  # overall amplitude of the mouth
    jaw_gain: float = 1.0  # jaw versus lips usage
    lip_gain: float = 1.0
    coarticulation: float = 1.0  # time scale of the dominance functions (larger: smoother)
    expressiveness: float = 1.0  # gain of the upper-face responses
    onset: float = 0.15  # s, ramp of an expression response
    decay: float = 0.8  # s, fade of an expression response
    blink_interval: tuple[float, float] = (2.0, 6.0)  # s between blinks
    blink_duration: tuple[float, float] = (0.15, 0.25)  # s

    @classmethod
    def for_speaker(cls, index: int) -> SpeakerStyle:
        """The style of speaker `index` (deterministic)."""
        u = np.frombuffer(hashlib.sha256(f"facegen-style-{index}".encode()).digest(), np.uint8) / 255.0
        lo = 2.0 + 1.0 * u[7]
        return cls(articulation=0.8 + 0.4 * u[0], jaw_gain=0.75 + 0.5 * u[1], lip_gain=0.75 + 0.5 * u[2],
                   coarticulation=0.8 + 0.45 * u[3], expressiveness=0.6 + 0.8 * u[4], onset=0.1 + 0.1 * u[5],
                   decay=0.6 + 0.4 * u[6], blink_interval=(lo, lo + 2.0 + 1.0 * u[8]))


# ------------------------------------------------------------------------------------------- visemes
def _v(**kw: float) -> np.ndarray:
    return np.array([kw.get(c, 0.0) for c in LOWER_CHANNELS])


# targets over LOWER_CHANNELS and dominance (jaw, lips) per viseme (a phone's visemes: facegen.phonetics). The
# vowels' jaw openings, the consonants' jaw dominances and the coarticulation times are fitted on real faces
# (benchmarks/calibrate_rig.py: the lip aperture of 11 GRID clips and the jaw of a real iPhone take of running
# speech; docs/real_faces.md): open vowels open widest (0.87 at a clip's median loudness: louder ones and
# wide-jawed speakers open up to 1, PROSODY_GAIN and the style's jaw_gain), schwa least (reduced in running
# speech); f/v's lip_close (0.9) brings the lower lip to the upper teeth (GRID's speakers at an f: 0.14 cm,
# a v: 0.22). The consonants' jaw sits where real speakers hold it, as a share of the vowels' around it
# (GRID's chin at the consonants' middles, docs/real_faces.md, twelfth pass): raised for an f/v (0.38; the
# iPhone take's jawOpen 0.14), which brings the lower lip to the upper teeth, lowered for an l (0.98: a low
# jaw avoids lateral contact and allows its apical articulation, Mooshammer et al. 2003).
VISEMES: dict[str, tuple[np.ndarray, float, float]] = {
    "rest": (_v(), 1.5, 1.5),
    "inhale": (_v(), 0.81, 1.0),  # lips parting before speech after a pause (PRE_SPEECH_S, PRE_SPEECH_JAW)
    "PBM": (_v(jaw_open=0.15, lip_close=1.0), 1.2, 2.5),  # the jaw part open (BILABIAL_JAW)
    "FV": (_v(jaw_open=0.08, lip_close=0.9, lower_lip_tuck=1.0, upper_lip_raise=0.25), 2.5, 3.0),
    "TH": (_v(jaw_open=0.15, lip_wide=0.15), 0.89, 0.8),
    "SZ": (_v(jaw_open=0.07, lip_wide=0.45), 1.19, 1.2),
    "SH": (_v(jaw_open=0.1, lip_funnel=1.0, lip_round=0.2), 0.72, 2.5),
    "TDN": (_v(jaw_open=0.15, lip_wide=0.1), 0.59, 0.3),
    "L": (_v(jaw_open=0.5), 0.59, 0.3),
    "R": (_v(jaw_open=0.12, lip_round=0.45, lip_funnel=0.35), 0.59, 2.0),
    "KG": (_v(jaw_open=0.2), 0.47, 0.3),
    "H": (_v(jaw_open=0.25), 0.18, 0.2),
    "W": (_v(jaw_open=0.05, lip_close=0.47, lip_round=1.0), 0.72, 3.0),  # pursed shut: neighbours part them
    "Y": (_v(jaw_open=0.1, lip_wide=0.5), 0.59, 1.5),
    "AA": (_v(jaw_open=0.87, lip_wide=0.1), 2.5, 1.0),
    "AE": (_v(jaw_open=0.87, lip_wide=0.3), 2.5, 1.0),
    "AH": (_v(jaw_open=0.29), 2.0, 0.8),  # schwa: reduced in running speech
    "ER": (_v(jaw_open=0.59, lip_round=0.3, lip_funnel=0.25), 2.0, 1.5),
    "EH": (_v(jaw_open=0.89, lip_wide=0.35), 2.0, 1.2),
    "IY": (_v(jaw_open=0.37, lip_wide=0.85), 2.0, 2.0),
    "IH": (_v(jaw_open=0.61, lip_wide=0.55), 2.0, 1.5),
    "AO": (_v(jaw_open=0.87, lip_round=0.55), 2.0, 2.0),
    "OW": (_v(jaw_open=0.79, lip_round=0.7), 2.0, 2.5),
    "UH": (_v(jaw_open=0.31, lip_round=0.6), 2.0, 2.5),
    "UW": (_v(jaw_open=0.155, lip_round=1.0), 2.0, 3.5),
}

# Rounded lips are pursed: a viseme's lips part the less the more it rounds, whatever the jaw does (GRID's
# speakers at the middle of a W: 0.15 cm, of UW: 0.50 cm, of open vowels 1.2-1.4 cm; docs/real_faces.md).
# A viseme's lip_close target is its own plus ROUND_CLOSE x its lip_round.
ROUND_CLOSE = 0.53
_CLOSE, _ROUND, _JAW = (LOWER_CHANNELS.index(c) for c in ("lip_close", "lip_round", "jaw_open"))


def held_target(vis: str) -> np.ndarray:
    """The pose [len(LOWER_CHANNELS)] viseme `vis` reaches when held: its VISEMES target, its lips pursed by
    ROUND_CLOSE as much as it rounds."""
    target = VISEMES[vis][0].copy()
    target[_CLOSE] = min(target[_CLOSE] + ROUND_CLOSE * target[_ROUND], 1.0)
    return target


VOWEL_APERTURE_DOMINANCE = 2.5  # vowels need the lips apart: they dominate lip_close strongly
ANTICIPATION_S = 0.1  # s, time constant of a segment's dominance before it (coarticulation ahead)
# The jaw anticipates less than the lips (lip rounding is the long-range gesture of coarticulation): on a
# real iPhone take of running speech a jaw that moves ahead by ANTICIPATION_S follows the capture's jawOpen
# at r 0.44, one that moves ahead by 0.05 s at 0.49, while GRID's lip aperture hardly tells them apart
# (r 0.741 / 0.739; benchmarks/calibrate_rig.py, docs/real_faces.md, sixth pass).
JAW_ANTICIPATION_S = 0.05  # s, the jaw channel's time constant ahead
CARRYOVER_S = 0.019  # s, after it
CLOSE_RAMP_S, JAW_CLOSE_RAMP_S = 0.034, 0.06  # s, the lips' and the jaw's ramps into and out of a p/b/m
# A p/b/m closes the lips (lip_close seals them whatever the jaw does); the jaw stays part open, as the vowels
# around it hold it: at the middle of a p/b/m real speakers' chin is 0.57 as far down as at the middle of a
# vowel (GRID, 14 bilabials, 10 speakers, tracked), 0.41 on a real iPhone take (jawOpen, 7). The rig shut it
# (jaw_open at most 0.06, PBM's jaw 0.04 with dominance 1.5: 0.11 of the vowels'); with BILABIAL_JAW 0.5 and
# the PBM viseme's jaw 0.15 at dominance 1.2 it is 0.50, the lips still closed at every p/b/m, GRID's lip r
# 0.744 / 0.747 -> 0.740 / 0.745 (fitted / held-out half), the take's jaw r 0.584 / 0.730 -> 0.604 / 0.739
# (docs/real_faces.md, eleventh pass).
BILABIAL_JAW = 0.5  # the jaw_open a p/b/m allows at most
# People part their lips before they speak after a pause (an in-breath: real speakers 0.02-0.43 s before the
# first sound, median 0.36 s, docs/real_faces.md): the last PRE_SPEECH_S of a pause of PAUSE_S or more opens
# the jaw to PRE_SPEECH_JAW.
PRE_SPEECH_S, PAUSE_S, PRE_SPEECH_JAW = 0.3, 0.3, 0.3

PROSODY_DB = 12.0  # dB of vowel loudness above (below) the clip's median that open the mouth 1 + PROSODY_GAIN
PROSODY_GAIN = 0.35  # (1 - PROSODY_GAIN) times wider (narrower); clipped to that range
STRESS_GAIN = 0.12  # stressed vowels open this much more, unstressed this much less
# How open a vowel is said shows in its first formant: F1 rises as the jaw lowers (Lindblom & Sundberg 1971).
# With `f1` (see formant_track) each vowel's jaw target is scaled by (its F1 / its viseme's usual F1, over
# the clip's median of that ratio: the speaker's vocal tract) ** FORMANT_EXP, clipped to 1/FORMANT_MAX to
# FORMANT_MAX: a reduced vowel closes the jaw, an emphatic one opens it, beyond what its phone says. The
# usual F1 are Hillenbrand et al. (1995)'s adult means (Hz); a diphthong's visemes take their own. Fitted on
# a real iPhone take and checked on GRID's lips (docs/real_faces.md, ninth pass).
VISEME_F1 = {"AA": 768.0, "AE": 588.0, "AH": 623.0, "AO": 652.0, "EH": 580.0, "ER": 474.0, "IH": 427.0,
             "IY": 342.0, "OW": 497.0, "UH": 469.0, "UW": 378.0}
FORMANT_EXP = 1.0
FORMANT_MAX = 2.0


def loudness_envelope(audio: np.ndarray, sample_rate: int, rate: float = 100.0) -> np.ndarray:
    """The clip's loudness in dB (RMS over 30 ms windows), sampled at `rate` Hz: what `viseme_curves`
    reads the prosody from."""
    audio = np.asarray(audio, np.float64)
    hop, win = max(1, round(sample_rate / rate)), max(1, int(0.03 * sample_rate))
    energy = np.concatenate([[0.0], np.cumsum(np.pad(audio, (win // 2, win)) ** 2)])
    power = (energy[win:] - energy[:-win])[::hop] / win
    n = int(np.ceil(len(audio) / hop))
    return (10 * np.log10(np.maximum(power[:n], 1e-10))).astype(np.float32)


def formant_track(audio: np.ndarray, sample_rate: int, rate: float = 100.0) -> np.ndarray:
    """The first formant (Hz) of the clip sampled at `rate` Hz, NaN where the sound is quiet (35 dB under its
    95th percentile) or shows no resonance: LPC of order 12 on 30 ms Hamming windows of the pre-emphasised
    audio at 10 kHz, the lowest pole above 200 Hz with a bandwidth under 500 Hz (the textbook estimate, as
    Praat's; librosa has the LPC but no formant tracker). `viseme_curves` reads the vowels' openness in it."""
    import librosa

    sr, order = 10000, 12
    x = librosa.resample(np.asarray(audio, np.float64), orig_sr=sample_rate, target_sr=sr)
    x = np.append(x[:1], x[1:] - 0.97 * x[:-1])
    hop, win = sr / rate, int(0.03 * sr)
    n = int(np.ceil(len(x) / hop))
    out = np.full(n, np.nan, np.float32)
    if n == 0:
        return out
    level = loudness_envelope(x, sr, rate)[:n]
    starts = np.round(np.arange(n) * hop).astype(int)
    keep = np.nonzero((level >= np.percentile(level, 95) - 35.0) & (starts + win // 2 <= len(x)))[0]
    keep = keep[starts[keep] >= win // 2]
    if len(keep) == 0:
        return out
    frames = np.lib.stride_tricks.sliding_window_view(x, win)[starts[keep] - win // 2] * np.hamming(win)
    coeffs = librosa.lpc(frames, order=order, axis=-1)  # [K, order + 1], coeffs[:, 0] = 1
    companion = np.zeros((len(keep), order, order))
    companion[:, 0, :] = -coeffs[:, 1:]
    companion[:, np.arange(1, order), np.arange(order - 1)] = 1.0
    roots = np.linalg.eigvals(companion)  # the poles of each window's all-pole filter
    freq = np.angle(roots) * sr / (2 * np.pi)
    bandwidth = -sr / np.pi * np.log(np.maximum(np.abs(roots), 1e-12))
    freq = np.where((np.imag(roots) > 0) & (freq > 200) & (bandwidth < 500), freq, np.inf)
    lowest = freq.min(axis=1)
    out[keep] = np.where(np.isfinite(lowest), lowest, np.nan)
    return out


def _phone_fields(phone) -> tuple[str, float, float]:
    if hasattr(phone, "text"):
        return str(phone.text), float(phone.start), float(phone.end)
    text, start, end = phone[0], phone[1], phone[2]
    return str(text), float(start), float(end)


_RATE = 200.0  # Hz, the time grid the curves are built on before averaging into frames


def _frame_average(values: np.ndarray, num_frames: int, fps: float) -> np.ndarray:
    """Average a curve sampled at _RATE over each frame's window [k - 1/2, k + 1/2] / fps."""
    n = len(values)
    t = np.arange(n) / _RATE
    frame = np.clip(np.floor(t * fps + 0.5).astype(int), 0, num_frames - 1)
    out = np.zeros((num_frames,) + values.shape[1:])
    np.add.at(out, frame, values)
    counts = np.bincount(frame, minlength=num_frames).astype(float)
    return out / np.maximum(counts, 1)[:, None]


def _formant_gains(segments: list, f1: np.ndarray | None, rate: float) -> list[float]:
    """Each segment's jaw gain from the first formant over its middle half (`viseme_curves`, FORMANT_EXP): 1
    for consonants, silence, vowels without a formant, and without `f1`."""
    gains = [1.0] * len(segments)
    if f1 is None or not FORMANT_EXP or not len(f1):
        return gains
    formant = np.asarray(f1, np.float64)

    def middle(start: float, end: float) -> float:
        a = int(np.clip((0.75 * start + 0.25 * end) * rate, 0, len(formant) - 1))
        values = formant[a:max(a + 1, int(np.ceil((0.25 * start + 0.75 * end) * rate)))]
        values = values[np.isfinite(values)]
        return float(np.median(values)) if len(values) else np.nan

    ratios = [middle(a, b) / VISEME_F1[vis] if vis in VISEME_F1 else np.nan for a, b, vis, _ in segments]
    known = [r for r in ratios if np.isfinite(r)]
    if not known:
        return gains
    speaker = float(np.median(known))
    return [float(np.clip((r / speaker) ** FORMANT_EXP, 1 / FORMANT_MAX, FORMANT_MAX))
            if np.isfinite(r) else 1.0 for r in ratios]


def viseme_curves(phones: Sequence, num_frames: int, fps: float = 25.0,
                  style: SpeakerStyle | None = None, *, alphabet: str = "espeak",
                  loudness: np.ndarray | None = None, loudness_rate: float = 100.0,
                  f1: np.ndarray | None = None) -> np.ndarray:
    """Lips and jaw [num_frames, len(LOWER_CHANNELS)] from phone timings (seconds; espeak mnemonics, or
    CMU phones with `alphabet="cmu"`).

    Coarticulation: Cohen-Massaro dominance functions (each segment's target is blended with its
    neighbours', weighted by dominances that fall off exponentially in time, with more anticipation
    than carry-over). Silence is the rest pose. During p, b and m the lips are closed (lip_close = 1)
    and the jaw no more than BILABIAL_JAW open; a bilabial shorter than a frame still closes the lips on its
    nearest frame.

    Prosody (as JALI's jaw and lip parameters): with `loudness` (dB sampled at `loudness_rate` Hz, see
    `loudness_envelope`) every vowel opens the jaw and shapes the lips more when it is louder than the
    clip's median vowel and less when quieter (PROSODY_DB, PROSODY_GAIN); stress marks on the phones add
    STRESS_GAIN. With `f1` (Hz at `loudness_rate`, see `formant_track`) each vowel's jaw opens as much more
    or less than its phone's as its first formant says (VISEME_F1, FORMANT_EXP). Without them, the curves are
    those of the phones alone.
    """
    check_alphabet(alphabet)
    style = style or SpeakerStyle()
    if num_frames <= 0:
        return np.zeros((0, len(LOWER_CHANNELS)), np.float32)
    duration = num_frames / fps
    n = int(np.ceil(duration * _RATE)) + 1
    t = np.arange(n) / _RATE
    segments: list[tuple[float, float, str, float]] = []  # start, end, viseme, gain
    cursor = 0.0
    bilabial: list[tuple[float, float]] = []
    vowel_db: list[float] = []
    for ph in phones:
        text, start, end = _phone_fields(ph)
        if end <= start:
            continue
        if start - cursor >= PAUSE_S and PRE_SPEECH_JAW > 0:
            breath = start - PRE_SPEECH_S
            segments += [(cursor, breath, "rest", 1.0), (breath, start, "inhale", 1.0)]
        elif start - cursor > 0.02:
            segments.append((cursor, start, "rest", 1.0))
        parts = phone_visemes(text, alphabet)
        stress = phone_stress(text, alphabet) if parts[0] in VOWEL_VISEMES else None
        gain = 1.0 if stress is None else 1.0 + STRESS_GAIN * (2 * stress - 1)
        step = (end - start) / len(parts)
        for k, vis in enumerate(parts):
            segments.append((start + k * step, start + (k + 1) * step, vis, gain))
        if parts == ("PBM",):
            bilabial.append((start, end))
        cursor = max(cursor, end)
    if duration - cursor > 0.0:
        segments.append((cursor, max(duration, cursor + 0.1), "rest", 1.0))
    if loudness is not None and len(loudness):
        loud = np.asarray(loudness, np.float64)

        def level(start: float, end: float) -> float:
            a = int(np.clip(start * loudness_rate, 0, len(loud) - 1))
            return float(loud[a:max(a + 1, int(np.ceil(end * loudness_rate)))].mean())

        levels = [level(a, b) if vis in VOWEL_VISEMES else np.nan for a, b, vis, _ in segments]
        vowel_db = [v for v in levels if np.isfinite(v)]
        if vowel_db:
            median = float(np.median(vowel_db))
            segments = [(a, b, vis, g * float(np.clip(1 + PROSODY_GAIN * (lv - median) / PROSODY_DB,
                                                        1 - PROSODY_GAIN, 1 + PROSODY_GAIN)))
                        if np.isfinite(lv) else (a, b, vis, g)
                        for (a, b, vis, g), lv in zip(segments, levels, strict=True)]

    jaw_gains = _formant_gains(segments, f1, loudness_rate)

    C = len(LOWER_CHANNELS)
    lips = np.array([c != "jaw_open" for c in LOWER_CHANNELS])
    is_close = np.array([c == "lip_close" for c in LOWER_CHANNELS])
    num = np.zeros((n, C))
    den = np.full((n, C), 1e-9)
    ahead = np.where(lips, ANTICIPATION_S, JAW_ANTICIPATION_S) * style.coarticulation  # [C]
    behind = CARRYOVER_S * style.coarticulation
    for (start, end, vis, gain), jaw_gain in zip(segments, jaw_gains, strict=True):
        _, dom_jaw, dom_lips = VISEMES[vis]
        target = _v(jaw_open=PRE_SPEECH_JAW) if vis == "inhale" else held_target(vis)
        if gain != 1.0:
            target = np.where(is_close, target, np.clip(target * gain, 0.0, 1.0))
        if jaw_gain != 1.0:
            target[_JAW] = min(target[_JAW] * jaw_gain, 1.0)
        centre, half = (start + end) / 2, (end - start) / 2
        dt = t - centre
        away = np.maximum(np.abs(dt) - half * (1.0 if vis == "rest" else 0.8), 0.0)
        rate = np.where((dt < 0)[:, None], 1 / ahead[None, :], 1 / behind)  # before the segment: anticipation
        dom = np.where(lips, dom_lips, dom_jaw)
        if vis in VOWEL_VISEMES:
            dom = np.where(is_close, VOWEL_APERTURE_DOMINANCE, dom)
        d = np.exp(-away[:, None] * rate) * dom[None, :]
        num += d * target[None, :]
        den += d
    curves = num / den

    # bilabial closure: lips closed over the phone, the jaw no more than BILABIAL_JAW open
    idx = {c: i for i, c in enumerate(LOWER_CHANNELS)}
    for start, end in bilabial:
        def envelope(ramp: float, start: float = start, end: float = end) -> np.ndarray:
            return np.clip(np.minimum(t - start + ramp, end + ramp - t) / ramp, 0, 1)

        env = envelope(CLOSE_RAMP_S)
        curves[:, idx["lip_close"]] = np.maximum(curves[:, idx["lip_close"]], env)
        env = envelope(JAW_CLOSE_RAMP_S)  # the jaw closes more slowly
        jaw = curves[:, idx["jaw_open"]]
        curves[:, idx["jaw_open"]] = jaw * (1 - env) + np.minimum(jaw, BILABIAL_JAW) * env
        for c in ("lip_wide", "lip_funnel", "lower_lip_tuck"):
            curves[:, idx[c]] *= 1 - 0.7 * env

    # speaker style
    gains = np.array([style.jaw_gain if c == "jaw_open" else (1.0 if c == "lip_close" else style.lip_gain)
                      for c in LOWER_CHANNELS]) * np.array(
        [1.0 if c == "lip_close" else style.articulation for c in LOWER_CHANNELS])
    curves = np.clip(curves * gains[None, :], 0.0, 1.0)
    out = _frame_average(curves, num_frames, fps)
    # every bilabial closes the lips on at least its nearest frame (even when shorter than a frame)
    frame_t = np.arange(num_frames) / fps
    for start, end in bilabial:
        inside = np.nonzero((frame_t >= start) & (frame_t <= end))[0]
        if len(inside) == 0:
            inside = np.array([int(np.clip(round((start + end) / 2 * fps), 0, num_frames - 1))])
        out[inside, idx["lip_close"]] = 1.0
        out[inside, idx["jaw_open"]] = np.minimum(out[inside, idx["jaw_open"]], BILABIAL_JAW)
    return out.astype(np.float32)


# ----------------------------------------------------------------------------------------- expression
def expression_response(t: np.ndarray, start: float, end: float, onset: float, decay: float) -> np.ndarray:
    """Shape of one response in [0, 1]: ramps up over `onset` from the word's start, holds through the
    word, then fades to 0 over `decay` seconds."""
    rise = np.clip((t - start) / onset, 0, 1)
    rise = rise * rise * (3 - 2 * rise)
    hold_end = max(end, start + onset)
    fall = np.clip((t - hold_end) / decay, 0, 1)
    fall = 1 - fall * fall * (3 - 2 * fall)
    return np.where(t < start, 0.0, rise * fall)


def expression_curves(words: Sequence, num_frames: int, fps: float = 25.0,
                      lexicon: dict[str, Emotion] | None = None,
                      style: SpeakerStyle | None = None) -> np.ndarray:
    """Upper face [num_frames, len(UPPER_CHANNELS)] from the meaning of the words alone.

    Every occurrence of a lexicon word (`words`: objects with .text, .start, .end in seconds) starts a
    response of its class (EXPRESSIONS) scaled by its intensity and the speaker's expressiveness;
    overlapping responses combine by maximum. Words outside the lexicon leave the upper face at rest.
    """
    style = style or SpeakerStyle()
    table = LEXICON if lexicon is None else lexicon
    t = np.arange(num_frames) / fps
    out = np.zeros((num_frames, len(UPPER_CHANNELS)))
    for word in words:
        text, start, end = (word.text, word.start, word.end) if hasattr(word, "text") else word[:3]
        emotion = lookup(str(text), table)
        if emotion is None:
            continue
        shape = expression_response(t, float(start), float(end), style.onset, style.decay)
        gain = emotion.intensity * style.expressiveness
        for channel, amount in EXPRESSIONS[emotion.cls].items():
            k = UPPER_CHANNELS.index(channel)
            out[:, k] = np.maximum(out[:, k], np.clip(gain * amount, 0, 1) * shape)
    return out.astype(np.float32)


# ---------------------------------------------------------------------------------------------- blinks
def blink_curves(num_frames: int, fps: float, rng: np.random.Generator,
                 style: SpeakerStyle | None = None) -> np.ndarray:
    """Random blinks [num_frames, 1]: every `style.blink_interval` seconds (uniform), each lasting
    `style.blink_duration` (closing 30%, closed 30%, opening 40% of it)."""
    style = style or SpeakerStyle()
    t = np.arange(num_frames) / fps
    out = np.zeros(num_frames)
    lo, hi = style.blink_interval
    when = float(rng.uniform(0.2, hi))
    end = num_frames / fps
    while when < end:
        dur = float(rng.uniform(*style.blink_duration))
        u = (t - when) / dur
        up = np.clip(u / 0.3, 0, 1)
        down = np.clip((1 - u) / 0.4, 0, 1)
        shape = np.where((u >= 0) & (u <= 1), np.minimum(up, down), 0.0)
        out = np.maximum(out, shape * shape * (3 - 2 * shape))
        when += dur + float(rng.uniform(lo, hi))
    return out[:, None].astype(np.float32)


def motion_curves(phones: Sequence, words: Sequence, num_frames: int, fps: float = 25.0,
                  style: SpeakerStyle | None = None, rng: np.random.Generator | None = None,
                  lexicon: dict[str, Emotion] | None = None, *, alphabet: str = "espeak",
                  loudness: np.ndarray | None = None, f1: np.ndarray | None = None) -> np.ndarray:
    """All rig channels [num_frames, len(CHANNELS)]: visemes, expressions and blinks, in CHANNELS order
    (`alphabet`, `loudness` and `f1`: see viseme_curves)."""
    rng = rng if rng is not None else np.random.default_rng(0)
    return np.concatenate([viseme_curves(phones, num_frames, fps, style, alphabet=alphabet,
                                         loudness=loudness, f1=f1),
                           expression_curves(words, num_frames, fps, lexicon, style),
                           blink_curves(num_frames, fps, rng, style)], 1)
