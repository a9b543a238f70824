"""Read audio and compute the model's mel features.

Features follow the paper: a 128-band mel power spectrogram in dB, one frame per animation frame
(hop = sample_rate / fps), exactly T = round(duration * fps) frames.

The mel filterbank comes from librosa (`librosa.filters.mel`) when a model is trained and is stored
in the model bundle with the rest of the feature configuration, so training and inference use the very
same numbers and the animate path never imports librosa (whose first numba-compiled calls cost seconds).
The STFT is torch's, which equals `librosa.stft` (Hann window, centred frames, zero padding); a test checks
our features against `librosa.feature.melspectrogram` + `librosa.power_to_db`.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from facegen.errors import FacegenError


@dataclass(frozen=True)
class FeatureConfig:
    """The feature settings a network is trained with (the mel spectrogram's and the text features'
    smoothing window, facegen.text); stored in every model bundle. A bundle written before a setting existed
    gets its default here, which is the value it was trained with."""

    sample_rate: int = 16000
    fps: float = 25.0
    n_mels: int = 128
    n_fft: int = 2048
    fmin: float = 0.0
    fmax: float | None = None
    amin: float = 1e-10  # floor of the power before the log: silence is -100 dB
    text_window: tuple[int, int] = (8, 7)  # frames before / after each frame in the text features' mean

    @property
    def hop_length(self) -> int:
        hop = self.sample_rate / self.fps if self.fps > 0 else 0.5  # nan and <= 0 fps divide nothing
        if abs(hop - round(hop)) > 1e-9:
            raise FacegenError(f"fps {self.fps} does not divide the sample rate {self.sample_rate}: choose "
                               "another fps")
        return round(hop)

    def to_dict(self) -> dict:
        """The settings as JSON values (the window as a list), for a bundle's header."""
        return dict(asdict(self), text_window=list(self.text_window))

    def mel_dict(self) -> dict:
        """The settings the mel spectrogram depends on (all but the text window): a cache key."""
        return {k: v for k, v in asdict(self).items() if k != "text_window"}

    @classmethod
    def from_dict(cls, d: dict) -> FeatureConfig:
        """Back from `to_dict` (or an older bundle's header, without the later settings)."""
        if "text_window" in d:
            d = dict(d, text_window=tuple(int(n) for n in d["text_window"]))
        return cls(**d)


def mel_filters(cfg: FeatureConfig) -> np.ndarray:
    """librosa's (Slaney) mel filterbank, [n_mels, 1 + n_fft // 2] float32."""
    from librosa.filters import mel

    return mel(sr=cfg.sample_rate, n_fft=cfg.n_fft, n_mels=cfg.n_mels, fmin=cfg.fmin,
               fmax=cfg.fmax).astype(np.float32)


MIN_SAMPLE_RATE, MAX_SAMPLE_RATE = 4000, 384000  # Hz: telephone speech to studio masters
MAX_SECONDS = 4 * 3600  # the longest audio facegen reads (an audiobook chapter, a long podcast)
HELD_BYTES = 512 << 20  # the most a clip's samples take at their own rate (float32): 2.3 h at 16 kHz
HELD_RATES = (44100, 32000, 24000, 22050, 16000)  # a longer clip's rate: the highest that fits, or 16 kHz


def load_audio(source: str | os.PathLike | bytes, what: str | None = None) -> tuple[np.ndarray, int]:
    """Read audio of any common format, rate, channel count and sample format: a file path, or the bytes of
    an encoded file (a WAV inside a USDZ package, the MP3 inside a GLB). The one place audio is read.

    Returns mono float32 samples in [-1, 1] (channels averaged) and their sample rate: the source's own,
    unless they would take more than HELD_BYTES (48 kHz audio over 46 minutes): then they are resampled as
    they are read to the highest of HELD_RATES that fits (at least 16 kHz, the rate the network and the
    aligner hear), so two hours at 48 kHz stereo take 460 MB, not 1.4 GB as float32 at 48 kHz.
    """
    import io

    import soundfile as sf

    if isinstance(source, bytes | bytearray | memoryview):
        name, handle = what or "the embedded audio", io.BytesIO(bytes(source))
        fix = "write the file again"
    else:
        path = Path(source)
        name, handle, fix = what or str(path), str(path), "pass a WAV, FLAC, OGG or MP3 file"
        if not path.exists():
            raise FacegenError(f"audio file {path} does not exist: check the path")
        if not path.is_file():
            raise FacegenError(f"{path} is not a file: pass an audio file (.wav, .flac, .ogg, .mp3)")
    try:
        with sf.SoundFile(handle) as f:
            sr = int(f.samplerate)
            if not MIN_SAMPLE_RATE <= sr <= MAX_SAMPLE_RATE:
                raise FacegenError(f"{name} says its sample rate is {sr} Hz; speech audio has "
                                   f"{MIN_SAMPLE_RATE}-{MAX_SAMPLE_RATE} Hz: re-export it")
            if f.frames > MAX_SECONDS * sr:  # as the header says: a lying one is read in bounded blocks below
                raise FacegenError(f"{name} is {f.frames / sr / 3600:.1f} hours long; facegen animates up to "
                                   f"{MAX_SECONDS // 3600} hours: cut it into parts")
            # block by block, the channels averaged as they come: a long stereo file never exists as floats.
            # (Not SoundFile.blocks: it sizes the last block by the header's frame count, an estimate for MP3,
            # and hands back the samples past the real end uninitialised.)
            rate = held_rate(sr, f.frames)
            stream = resampler(sr, rate) if rate != sr else None
            samples, read = _Samples(f.frames * rate // sr + 64), 0
            while len(block := f.read(1 << 20, dtype="float32", always_2d=True)):
                read += len(block)
                if read > MAX_SECONDS * sr:  # a header that understates the length
                    raise FacegenError(f"{name} is longer than {MAX_SECONDS // 3600} hours; facegen animates "
                                       f"up to {MAX_SECONDS // 3600} hours: cut it into parts")
                mono = block.mean(axis=1) if block.shape[1] > 1 else block[:, 0]
                samples.add(stream.resample_chunk(mono) if stream is not None else mono)
            if stream is not None:
                samples.add(stream.resample_chunk(np.zeros(0, np.float32), last=True))
    except sf.LibsndfileError as exc:
        raise FacegenError(
            f"cannot read {name} as audio ({exc.error_string if hasattr(exc, 'error_string') else exc}): "
            f"{fix}"
        ) from exc
    except (OSError, RuntimeError, TypeError) as exc:
        raise FacegenError(f"cannot read {name} as audio ({exc}): {fix}") from exc
    samples = samples.array()
    if not all_finite(samples):
        raise FacegenError(f"audio {name} contains NaN or infinite samples: re-export it")
    return samples, int(rate)


class _Samples:
    """Samples read block by block into one array, sized by the header (its pages are only taken as they are
    written) and doubled when a header understated the length: the samples exist once, never also as a list
    of blocks (whose freed memory the allocator may keep)."""

    def __init__(self, expected: int) -> None:
        self.buffer, self.size = np.empty(max(expected, 1 << 16), np.float32), 0

    def add(self, block: np.ndarray) -> None:
        if self.size + len(block) > len(self.buffer):
            grown = np.empty(max(2 * len(self.buffer), self.size + len(block)), np.float32)
            grown[:self.size] = self.buffer[:self.size]
            self.buffer = grown
        self.buffer[self.size:self.size + len(block)] = block
        self.size += len(block)

    def array(self) -> np.ndarray:
        return self.buffer[:self.size]


def held_rate(rate: int, frames: int) -> int:
    """The rate `frames` samples at `rate` are held at: their own if they fit in HELD_BYTES, else the highest
    of HELD_RATES below it that fits (16 kHz at least)."""
    if frames * 4 <= HELD_BYTES:
        return rate
    fits = [r for r in HELD_RATES if r < rate and frames * r / rate * 4 <= HELD_BYTES]
    return max(fits) if fits else min(rate, HELD_RATES[-1])


def write_wav(samples: np.ndarray, sample_rate: int, path: str | os.PathLike,
              subtype: str = "PCM_16") -> Path:
    """Write mono audio as a WAV file (16-bit PCM by default, samples clipped to [-1, 1]; "FLOAT" keeps
    them as they are). The one place audio is written; callers that need atomicity pass a temporary path."""
    import soundfile as sf

    samples = np.asarray(samples).reshape(-1)
    with sf.SoundFile(str(path), "w", samplerate=int(sample_rate), channels=1, subtype=subtype,
                      format="WAV") as file:
        for s in range(0, len(samples), 1 << 22):  # a block at a time: no clipped copy of a long clip
            block = np.asarray(samples[s:s + (1 << 22)], dtype=np.float32)
            file.write(np.clip(block, -1.0, 1.0) if subtype.startswith("PCM") else block)
    return Path(path)


RESAMPLE_BLOCK = 1 << 20  # samples resampled at a time


def resample(samples: np.ndarray, orig_sr: int, target_sr: int) -> np.ndarray:
    """Resample with soxr (librosa's default resampler), float32 out: through its stream, a block at a time
    (the same samples as in one call, which would hold a long clip's input as float32 twice)."""
    if orig_sr == target_sr:
        return samples.astype(np.float32, copy=False)
    stream = resampler(orig_sr, target_sr)
    parts = [stream.resample_chunk(np.asarray(samples[s:s + RESAMPLE_BLOCK], np.float32))
             for s in range(0, len(samples), RESAMPLE_BLOCK)]
    parts.append(stream.resample_chunk(np.zeros(0, np.float32), last=True))
    return np.concatenate(parts)


def resampler(orig_sr: int, target_sr: int):
    """soxr's stream resampler of mono float32 audio (quality HQ, librosa's default)."""
    import soxr

    return soxr.ResampleStream(orig_sr, target_sr, 1, dtype="float32", quality="HQ")


def num_frames(duration: float, fps: float) -> int:
    """The number of animation frames of a clip: round(duration * fps)."""
    return round(duration * fps)


SILENT_PEAK = 1e-4  # -80 dBFS: audio whose peak stays below this holds no speech


def is_silent(samples: np.ndarray) -> bool:
    """Whether `samples` peak below -80 dBFS (no speech to align or hear)."""
    return len(samples) == 0 or peak(samples) < SILENT_PEAK


def all_finite(samples: np.ndarray) -> bool:
    """Whether no sample is NaN or infinite, a block at a time."""
    return all(np.isfinite(samples[s:s + (1 << 22)]).all() for s in range(0, len(samples), 1 << 22))


def peak(samples: np.ndarray) -> float:
    """The largest absolute sample, a block at a time (no second copy of a long clip)."""
    return max((float(np.abs(samples[s:s + (1 << 22)]).max()) for s in range(0, len(samples), 1 << 22)),
               default=0.0)


def check_speech(samples: np.ndarray, sr: int, fps: float, name: str = "audio",
                 silence_ok: bool = False) -> None:
    """Refuse audio that cannot be animated: shorter than one frame, or silent (unless `silence_ok`: a silent
    clip animates as an idle face)."""
    if num_frames(len(samples) / sr, fps) < 1:
        raise FacegenError(
            f"{name} is {len(samples) / sr * 1000:.0f} ms long, shorter than one frame at {fps:g} fps: "
            "pass a longer recording"
        )
    if not silence_ok and is_silent(samples):
        raise FacegenError(f"{name} is silent (peak below -80 dBFS): pass a recording with speech")


MEL_FRAMES = 2048  # spectrogram frames computed at a time (their 2048-point spectra: 17 MB)


def mel_features(
    samples: np.ndarray, sr: int, cfg: FeatureConfig, filters: np.ndarray | None = None
) -> np.ndarray:
    """Mel power spectrogram in dB, [T, n_mels] float32 with T = round(duration * fps).

    Computed MEL_FRAMES frames at a time, each block from the samples under it: the same numbers as one
    centred STFT over the clip, in bounded memory (a 2-hour clip's spectra alone would take 1.5 GB) and in
    short calls (a signal can stop it). numpy's FFT, not torch.stft: torch's chose another transform in about
    one process in ten (up to 0.05 dB apart), so the same input and seed gave other output files."""
    if filters is None:
        filters = mel_filters(cfg)
    y = resample(samples, sr, cfg.sample_rate)
    T = num_frames(len(samples) / sr, cfg.fps)
    hop, pad = cfg.hop_length, cfg.n_fft // 2
    frames = 1 + max(len(y), pad + 1) // hop  # a centred STFT's frames (a short signal is padded)
    window = (0.5 - 0.5 * np.cos(2 * np.pi * np.arange(cfg.n_fft) / cfg.n_fft)).astype(np.float32)  # periodic
    bank = np.asarray(filters, np.float32).T  # [F, n_mels]
    feats = np.empty((T, cfg.n_mels), np.float32)
    for first in range(0, frames, MEL_FRAMES):
        last = min(first + MEL_FRAMES, frames)
        start, stop = first * hop - pad, (last - 1) * hop - pad + cfg.n_fft  # the samples under them
        piece = np.zeros(stop - start, np.float32)  # zeros beyond the signal, as the centred STFT's
        inside = y[max(start, 0):max(min(stop, len(y)), 0)]
        piece[max(-start, 0):max(-start, 0) + len(inside)] = inside
        framed = np.lib.stride_tricks.sliding_window_view(piece, cfg.n_fft)[::hop] * window  # [frames, n_fft]
        spec = np.fft.rfft(framed, axis=1)
        power = (spec.real ** 2 + spec.imag ** 2).astype(np.float32, copy=False)  # [frames, F]
        db = 10.0 * np.log10(np.maximum(power @ bank, cfg.amin))
        feats[first:min(last, T)] = db[:max(min(last, T) - first, 0)]
    if 0 < frames < T:  # can only be short by a frame or so: repeat the last one
        feats[frames:] = feats[frames - 1]
    return feats
