"""MP3 for audio embedded in glTF (KHR_audio_emitter allows audio/mpeg): encode, decode, sync.

Every MP3 encoder delays the sound: LAME (the encoder of ffmpeg and libsndfile) adds 576 samples and the
decoder's synthesis filter 529 more, 1105 in all (69 ms at 16 kHz). A "LAME/Xing" header can tell a
decoder to drop them, but not every decoder reads it (and one that does not plays the header frame as
extra silence). So the MP3 is written without that header and the delay is removed from the front of the
input instead: every decoder then plays sample n of the clip at time n / rate, and sound and motion stay
in sync. The delay is measured, not assumed: a probe signal is encoded, decoded back and cross-correlated
(cached per sample rate and bitrate). The cost: the clip's first 1105 samples are not in the MP3 (clips
start with silence; the WAV sidecar keeps them).
"""

from __future__ import annotations

import functools
from math import gcd

import numpy as np

from facegen.errors import FacegenError
from facegen.processes import run_tool

MP3_RATES = (8000, 11025, 12000, 16000, 22050, 24000, 32000, 44100, 48000)


def bitrate_for(sample_rate: int) -> int:
    """kbit/s for mono speech: 32 up to 16 kHz, 48 up to 24 kHz, 64 above."""
    return 32 if sample_rate <= 16000 else 48 if sample_rate <= 24000 else 64


def mp3_rate(sample_rate: int) -> int:
    """The sample rate the MP3 is written at: the clip's own when MP3 allows it, else the next one up."""
    if sample_rate in MP3_RATES:
        return int(sample_rate)
    return next((r for r in MP3_RATES if r >= sample_rate), MP3_RATES[-1])


def encode(audio: np.ndarray, sample_rate: int, *, compensate: bool = True) -> tuple[bytes, dict]:
    """MP3 bytes of mono `audio` (no Xing/LAME header) and facts about them: sampleRate, bitrate (kbit/s),
    samples (of the input, at sampleRate) and delayCompensated (samples trimmed from the front)."""
    samples = np.clip(np.asarray(audio, dtype=np.float32).reshape(-1), -1.0, 1.0)
    rate = mp3_rate(int(sample_rate))
    if rate != sample_rate:
        from scipy.signal import resample_poly

        g = gcd(int(sample_rate), rate)
        samples = resample_poly(samples, rate // g, int(sample_rate) // g).astype(np.float32)
    kbps = bitrate_for(rate)
    delay = measured_delay(rate, kbps) if compensate else 0
    body = samples[delay:]
    if len(body) < 1152:  # a clip shorter than the delay: one MP3 frame of what is left, then silence
        body = np.concatenate([body, np.zeros(1152 - len(body), np.float32)])
    data = _lame(body, rate, kbps)
    return data, {"sampleRate": rate, "bitrate": kbps, "samples": len(samples), "delayCompensated": delay}


def decode(data: bytes) -> tuple[np.ndarray, int]:
    """Decode MP3 bytes to mono float32 samples and their rate (libsndfile/mpg123)."""
    from facegen.audio import load_audio

    return load_audio(data, what="the embedded MP3 audio")


def lag(decoded: np.ndarray, original: np.ndarray) -> int:
    """How many samples `decoded` lags `original` (cross-correlation peak; negative: it leads)."""
    n = len(decoded) + len(original)
    size = 1 << (n - 1).bit_length()
    spectrum = np.fft.rfft(decoded, size) * np.conj(np.fft.rfft(original, size))
    corr = np.fft.irfft(spectrum, size)
    peak = int(np.argmax(corr))
    return peak if peak < size // 2 else peak - size


@functools.cache
def measured_delay(sample_rate: int, kbps: int) -> int:
    """The encoder+decoder delay in samples at this rate and bitrate, measured on a probe signal."""
    rng = np.random.default_rng(1)
    probe = np.zeros(sample_rate, np.float32)
    burst = slice(sample_rate // 5, sample_rate // 2)
    probe[burst] = 0.3 * rng.standard_normal(burst.stop - burst.start).astype(np.float32)
    decoded, rate = decode(_lame(probe, sample_rate, kbps))
    delay = lag(decoded, probe)
    if rate != sample_rate or not 0 <= delay < 4 * 1152:
        raise FacegenError(f"the MP3 encoder delay measured {delay} samples at {rate} Hz: the encoder is "
                           "broken")
    return delay


def _lame(samples: np.ndarray, sample_rate: int, kbps: int) -> bytes:
    """Encode with ffmpeg's libmp3lame (the binary that imageio-ffmpeg ships), without a Xing header."""
    args = [
        "-hide_banner", "-loglevel", "error", "-nostdin",
        "-f", "f32le", "-ar", str(sample_rate), "-ac", "1", "-i", "pipe:0",
        "-c:a", "libmp3lame", "-b:a", f"{kbps}k", "-write_xing", "0", "-id3v2_version", "0",
        "-f", "mp3", "pipe:1",
    ]
    done = run_tool("ffmpeg", args, input=np.ascontiguousarray(samples, np.float32).tobytes(), timeout=600)
    if done.returncode != 0 or not done.stdout:
        message = done.stderr.decode(errors="replace").strip().splitlines()
        raise FacegenError(
            f"ffmpeg could not encode MP3 ({message[-1] if message else 'no output'}): "
            "reinstall imageio-ffmpeg, or write without audio"
        )
    return done.stdout
