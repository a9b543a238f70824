"""Acoustic augmentation of mono float32 speech, so a model trained on synthetic voices hears what
recordings sound like: the speaker's loudness drifting (`loudness_drift`, drawn apart from the chain: the
training motion's prosody follows it), pitch and formant (vocal-tract length) shifts, tempo, additive noise,
room reverberation, band limits, lossy codec round trips and level. Each step is a function; `augment` draws a
random chain of them from an `AugmentSpec` with a numpy Generator, deterministically for a given seed.

Only `tempo` changes durations: it returns the factor by which phone and word times scale. Every other step
keeps the timing (zero-phase filters, the reverb's direct path at lag 0, the codecs' delay measured and
removed).
"""

from __future__ import annotations

import functools
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facegen.audio import load_audio, write_wav
from facegen.errors import FacegenError

NOISE_KINDS = ("white", "pink", "babble")
CODECS = ("mp3", "ogg")


@dataclass(frozen=True)
class AugmentSpec:
    """Probability of each step (`p_*`) and the range its parameter is drawn from (uniformly; tuples of
    choices where the parameter is discrete). The level step is always applied unless `p_level` < 1."""

    p_pitch: float = 0.5
    semitones: tuple[float, float] = (-3.0, 3.0)
    p_formant: float = 0.5
    formant_factor: tuple[float, float] = (0.9, 1.1)
    p_tempo: float = 0.5
    tempo_factor: tuple[float, float] = (0.9, 1.1)
    p_reverb: float = 0.3
    rt60: tuple[float, float] = (0.2, 0.8)
    drr_db: tuple[float, float] = (0.0, 10.0)
    p_noise: float = 0.5
    snr_db: tuple[float, float] = (5.0, 30.0)
    noise_kinds: tuple[str, ...] = NOISE_KINDS
    p_band: float = 0.3
    lowpass_hz: tuple[float, float] = (4000.0, 8000.0)
    p_codec: float = 0.2
    mp3_kbps: tuple[int, ...] = (32, 40, 48, 56, 64)
    ogg_quality: tuple[int, ...] = (0, 1, 2, 3)
    p_level: float = 1.0
    level_dbfs: tuple[float, float] = (-35.0, -10.0)


def rms_dbfs(audio: np.ndarray) -> float:
    """Level in dBFS: 20 log10 of the RMS over the whole clip (a full-scale square wave is 0 dBFS)."""
    return float(20.0 * np.log10(np.sqrt(np.mean(np.square(audio, dtype=np.float64))) + 1e-12))


def pitch_shift(audio: np.ndarray, sr: int, semitones: float) -> np.ndarray:
    """Shift pitch (and with it the whole spectrum) by `semitones`, keeping the duration: librosa's
    phase-vocoder stretch followed by resampling; the level kept."""
    import librosa

    shifted = librosa.effects.pitch_shift(audio, sr=sr, n_steps=float(semitones), n_fft=_n_fft(sr))
    return _match_rms(shifted, audio)


def formant_shift(audio: np.ndarray, sr: int, factor: float) -> np.ndarray:
    """Vocal-tract-length perturbation: scale the formants by `factor` (>1: a shorter tract) while the pitch
    and the duration stay. Method: per STFT frame, the spectral envelope is the real cepstrum liftered below
    1.5 ms (shorter than any pitch period up to 660 Hz, so it holds the formants, not the harmonics); the
    frame's spectrum is divided by its envelope and multiplied by the envelope read at f / factor, then
    resynthesised with the original phases; the level kept. (Resampling plus a time stretch would scale pitch
    and formants together, which `pitch_shift` already does.)"""
    import librosa

    n, n_fft = len(audio), _n_fft(sr)
    spec = librosa.stft(audio, n_fft=n_fft, hop_length=n_fft // 4)
    log_mag = np.log(np.abs(spec) + 1e-8)
    cep = np.fft.irfft(log_mag, n=n_fft, axis=0)
    keep = max(int(0.0015 * sr), 8)
    cep[keep:n_fft - keep + 1] = 0.0
    envelope = np.fft.rfft(cep, axis=0).real
    bins = np.arange(envelope.shape[0], dtype=np.float64)
    src = np.clip(bins / factor, 0, bins[-1])
    lo = np.floor(src).astype(int)
    hi = np.minimum(lo + 1, len(bins) - 1)
    w = (src - lo)[:, None]
    warped = envelope[lo] * (1 - w) + envelope[hi] * w
    out = librosa.istft(spec * np.exp(warped - envelope), hop_length=n_fft // 4, n_fft=n_fft, length=n)
    return _match_rms(out, audio)


def tempo(audio: np.ndarray, sr: int, factor: float) -> tuple[np.ndarray, float]:
    """Speak `factor` times faster (phase-vocoder time stretch, pitch kept). Returns the audio and the time
    scale: multiply phone and word times by it (the exact ratio of the new to the old duration)."""
    import librosa

    out = _match_rms(librosa.effects.time_stretch(audio, rate=float(factor), n_fft=_n_fft(sr)), audio)
    return out, len(out) / len(audio)


def _n_fft(sr: int) -> int:
    """A 32 ms STFT window (librosa's default 2048 points smear speech onsets by up to 64 ms at 16 kHz)."""
    return 1 << int(np.ceil(np.log2(0.032 * sr)))


def _match_rms(out: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """`out` at the RMS of `ref` (librosa's phase vocoder loses ~3 dB on speech to phase incoherence)."""
    rms_out = np.sqrt(np.mean(np.square(out, dtype=np.float64)))
    rms_ref = np.sqrt(np.mean(np.square(ref, dtype=np.float64)))
    return (out * (rms_ref / rms_out if rms_out > 0 else 1.0)).astype(np.float32)


def make_noise(audio: np.ndarray, kind: str, rng: np.random.Generator) -> np.ndarray:
    """Noise as long as `audio`: white, pink (1/f power) or babble (five circularly shifted, some reversed,
    copies of the clip itself: speech-shaped and unintelligible)."""
    n = len(audio)
    if kind == "white":
        return rng.standard_normal(n)
    if kind == "pink":
        spectrum = np.fft.rfft(rng.standard_normal(n))
        f = np.arange(len(spectrum), dtype=np.float64)
        f[0] = 1.0
        return np.fft.irfft(spectrum / np.sqrt(f), n=n)
    if kind == "babble":
        out = np.zeros(n)
        for _ in range(5):
            copy = np.roll(audio.astype(np.float64), int(rng.integers(n)))
            out += copy[::-1] if rng.random() < 0.5 else copy
        return out
    raise FacegenError(f"unknown noise kind {kind!r}: choose one of {', '.join(NOISE_KINDS)}")


def add_noise(audio: np.ndarray, snr_db: float, noise: np.ndarray) -> np.ndarray:
    """Add `noise` scaled so the clip-to-noise power ratio (both over the whole clip) is `snr_db`."""
    p_sig = np.mean(np.square(audio, dtype=np.float64))
    p_noise = np.mean(np.square(noise, dtype=np.float64))
    if p_sig <= 0 or p_noise <= 0:
        return audio.copy()
    gain = np.sqrt(p_sig / (p_noise * 10.0 ** (snr_db / 10.0)))
    return (audio + gain * noise).astype(np.float32)


def room_impulse_response(sr: int, rt60: float, drr_db: float, rng: np.random.Generator) -> np.ndarray:
    """A synthetic room: a unit direct path at lag 0, then (after 2.5 ms) Gaussian noise under an exponential
    envelope falling 60 dB in `rt60` seconds, scaled so direct/reverberant energy is `drr_db`."""
    n = int(1.2 * rt60 * sr)
    t = np.arange(n) / sr
    tail = rng.standard_normal(n) * np.exp(-np.log(1000.0) * t / rt60)
    tail[: int(0.0025 * sr) + 1] = 0.0
    tail *= np.sqrt(10.0 ** (-drr_db / 10.0) / np.sum(tail**2))
    tail[0] = 1.0
    return tail


def reverb(audio: np.ndarray, ir: np.ndarray) -> np.ndarray:
    """Convolve with an impulse response (direct path at lag 0, so timings stay), cut to the clip's length and
    brought back to the clip's RMS."""
    from scipy.signal import fftconvolve

    return _match_rms(fftconvolve(audio.astype(np.float64), ir)[: len(audio)], audio)


def band_limit(audio: np.ndarray, sr: int, low: float | None, high: float | None) -> np.ndarray:
    """Zero-phase (forward-backward) 8th-order Butterworth: high-pass at `low`, low-pass at `high` (None: no
    edge). Telephone band: low=300, high=3400."""
    from scipy.signal import butter, sosfiltfilt

    edges = [f for f in (low, high) if f is not None]
    if not edges:
        return audio.copy()
    btype = "bandpass" if len(edges) == 2 else ("highpass" if low is not None else "lowpass")
    sos = butter(8, edges if len(edges) == 2 else edges[0], btype=btype, fs=sr, output="sos")
    return sosfiltfilt(sos, audio.astype(np.float64)).astype(np.float32)


def _ffmpeg(args: list[str], what: str) -> None:
    from facegen.processes import run_tool

    try:
        proc = run_tool("ffmpeg", ["-y", "-nostdin", "-v", "error", *args], text=True, timeout=120)
    except subprocess.TimeoutExpired as exc:
        raise FacegenError(f"ffmpeg did not finish {what} within 120 s") from exc
    if proc.returncode != 0:
        lines = proc.stderr.strip().splitlines() or ["no message"]
        raise FacegenError(f"ffmpeg failed {what} ({lines[-1]}): check the codec takes this sample rate")


def _round_trip(audio: np.ndarray, sr: int, codec: str, setting: int) -> np.ndarray:
    """Encode and decode with ffmpeg, without any delay correction; the decoded samples at `sr`."""
    if codec == "mp3":
        ext, enc = "mp3", ["-c:a", "libmp3lame", "-b:a", f"{setting}k"]
    elif codec == "ogg":
        ext, enc = "ogg", ["-c:a", "libvorbis", "-q:a", str(setting)]
    else:
        raise FacegenError(f"unknown codec {codec!r}: choose one of {', '.join(CODECS)}")
    with tempfile.TemporaryDirectory(prefix="facegen-codec-") as tmp:
        src, coded, back = Path(tmp) / "in.wav", Path(tmp) / f"coded.{ext}", Path(tmp) / "back.wav"
        write_wav(audio, sr, src, subtype="FLOAT")
        _ffmpeg(["-i", str(src), *enc, str(coded)], f"encoding {codec}")
        _ffmpeg(["-i", str(coded), "-ac", "1", "-ar", str(sr), "-c:a", "pcm_f32le", str(back)],
                f"decoding {codec}")
        return load_audio(back, what=f"the decoded {codec}")[0]


@functools.lru_cache(maxsize=64)
def codec_delay(codec: str, sr: int, setting: int) -> int:
    """The codec round trip's delay in samples, measured by cross-correlating a noise-burst probe with its
    round trip (0 when the decoder honours the LAME/Vorbis delay headers, as ffmpeg does)."""
    from scipy.signal import correlate

    probe = np.zeros(int(1.5 * sr), dtype=np.float32)
    probe[sr // 2: sr] = 0.2 * np.random.default_rng(0).standard_normal(sr // 2)
    back = _round_trip(probe, sr, codec, setting)
    corr = correlate(back, probe, mode="full", method="fft")
    return int(np.argmax(corr)) - (len(probe) - 1)


def codec_round_trip(audio: np.ndarray, sr: int, codec: str, setting: int) -> np.ndarray:
    """A lossy round trip through ffmpeg: "mp3" at `setting` kbps (libmp3lame) or "ogg" Vorbis at quality
    `setting`; the codec delay removed and the length kept, so timings stay aligned."""
    back = _round_trip(audio, sr, codec, setting)
    delay = codec_delay(codec, sr, setting)
    back = back[delay:] if delay >= 0 else np.concatenate([np.zeros(-delay, np.float32), back])
    out = np.zeros(len(audio), dtype=np.float32)
    out[: min(len(back), len(audio))] = back[: len(audio)]
    return out


def normalize_level(audio: np.ndarray, dbfs: float) -> np.ndarray:
    """Scale to `dbfs` (see `rms_dbfs`); peaks that would pass 0.7 go through a soft tanh knee to at most
    0.99, so nothing clips (the gain is re-solved after the knee, so the level still lands on the target)."""
    x = audio.astype(np.float64)
    target = 10.0 ** (dbfs / 20.0)
    gain = 1.0
    for _ in range(8):
        y = _soft_limit(x * gain)
        rms = np.sqrt(np.mean(y**2))
        if rms <= 0 or abs(20 * np.log10(rms / target)) < 0.01:
            break
        gain *= target / rms
    return y.astype(np.float32)


def _soft_limit(x: np.ndarray, knee: float = 0.7, ceiling: float = 0.99) -> np.ndarray:
    mag = np.abs(x)
    over = mag > knee
    mag[over] = knee + (ceiling - knee) * np.tanh((mag[over] - knee) / (ceiling - knee))
    return np.sign(x) * mag


# The speaker's loudness drifts: real speech grows quieter toward a phrase's end (declination) and swells
# and fades with emphasis and the distance to the microphone, by several dB; synthetic voices hold their
# level. (One GRID clip's quiet final "now" came out nearly shut from a model trained without it; over the
# 11 clips the model followed a word's loudness no more than the rig does: benchmarks/loudness_response.py,
# docs/real_faces.md.) `loudness_drift` is drawn before the training motion's loudness is taken, so the
# motion follows the drift only as the rig's prosody does (facegen.synth.curves.PROSODY_GAIN: at most 35 %
# for 12 dB).
DRIFT_P = 0.7  # share of takes that drift
DECLINATION_DB = (-9.0, 2.0)  # level at the end against the start, drawn uniformly
WOBBLE_DB = 3.0  # standard deviation of the slow swells, one knot per WOBBLE_S
WOBBLE_S = 0.5
DRIFT_LIMIT_DB = 12.0


def loudness_drift(audio: np.ndarray, sr: int, rng: np.random.Generator | int,
                   p: float = DRIFT_P) -> tuple[np.ndarray, dict | None]:
    """`audio` under a slow random gain (with probability `p`): a linear declination of DECLINATION_DB over
    the clip plus smooth swells (a natural cubic spline through knots WOBBLE_S apart, N(0, WOBBLE_DB)),
    within +-DRIFT_LIMIT_DB. Returns (audio, the drift's parameters or None when none was drawn)."""
    from scipy.interpolate import CubicSpline

    rng = np.random.default_rng(rng)
    audio = np.asarray(audio, dtype=np.float32)
    if rng.random() >= p or len(audio) < 2:
        return audio, None
    duration = len(audio) / sr
    declination = float(rng.uniform(*DECLINATION_DB))
    knots = np.linspace(0.0, duration, max(2, int(np.ceil(duration / WOBBLE_S)) + 1))
    swells = rng.normal(0.0, WOBBLE_DB, len(knots))
    coarse = np.linspace(0.0, duration, max(2, int(duration * 100)) + 1)  # the gain at 100 Hz
    curve = declination * coarse / duration + CubicSpline(knots, swells, bc_type="natural")(coarse)
    curve = np.clip(curve, -DRIFT_LIMIT_DB, DRIFT_LIMIT_DB)
    gain = 10.0 ** (np.interp(np.arange(len(audio)) / sr, coarse, curve) / 20.0)
    return (audio * gain).astype(np.float32), {"declination_db": round(declination, 3),
                                               "swells_db": [round(float(x), 3) for x in swells]}


def augment(audio: np.ndarray, sr: int, rng: np.random.Generator | int,
            spec: AugmentSpec | None = None) -> tuple[np.ndarray, float, dict]:
    """A random chain over `audio`: pitch, formants, tempo (the speaker), reverb, noise (the room), band
    limit, codec (the channel), level. Returns (audio, time_scale, what was applied with its parameters)."""
    spec = spec or AugmentSpec()
    rng = np.random.default_rng(rng)
    out = np.asarray(audio, dtype=np.float32)
    scale, applied = 1.0, {}
    if rng.random() < spec.p_pitch:
        applied["pitch_semitones"] = float(rng.uniform(*spec.semitones))
        out = pitch_shift(out, sr, applied["pitch_semitones"])
    if rng.random() < spec.p_formant:
        applied["formant_factor"] = float(rng.uniform(*spec.formant_factor))
        out = formant_shift(out, sr, applied["formant_factor"])
    if rng.random() < spec.p_tempo:
        applied["tempo_factor"] = float(rng.uniform(*spec.tempo_factor))
        out, scale = tempo(out, sr, applied["tempo_factor"])
    if rng.random() < spec.p_reverb:
        rt60, drr = float(rng.uniform(*spec.rt60)), float(rng.uniform(*spec.drr_db))
        applied["reverb"] = {"rt60": rt60, "drr_db": drr}
        out = reverb(out, room_impulse_response(sr, rt60, drr, rng))
    if rng.random() < spec.p_noise:
        kind, snr = str(rng.choice(spec.noise_kinds)), float(rng.uniform(*spec.snr_db))
        applied["noise"] = {"kind": kind, "snr_db": snr}
        out = add_noise(out, snr, make_noise(out, kind, rng))
    if rng.random() < spec.p_band:
        low, high = (300.0, 3400.0) if rng.random() < 0.5 else (None, float(rng.uniform(*spec.lowpass_hz)))
        if high < 0.95 * sr / 2:
            applied["band_hz"] = [low, high]
            out = band_limit(out, sr, low, high)
    if rng.random() < spec.p_codec:
        name = str(rng.choice(CODECS))
        setting = int(rng.choice(spec.mp3_kbps if name == "mp3" else spec.ogg_quality))
        applied["codec"] = {"codec": name, "kbps" if name == "mp3" else "quality": setting}
        out = codec_round_trip(out, sr, name, setting)
    if rng.random() < spec.p_level:
        applied["level_dbfs"] = float(rng.uniform(*spec.level_dbfs))
        out = normalize_level(out, applied["level_dbfs"])
    return out, scale, applied
