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


def load_audio(source: str | os.PathLike | bytes, what: str | None = None) -> tuple[np.ndarray, int]:
    """Read audio of any common format, rate, channel count and sample format: a file path, or the bytes of
    an encoded file (a WAV inside a USDZ package, the MP3 inside a GLB). The one place audio is read.

    Returns mono float32 samples in [-1, 1] (channels averaged) at the source's own sample rate.
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
            blocks = []
            while len(block := f.read(1 << 20, dtype="float32", always_2d=True)):
                blocks.append(block.mean(axis=1) if block.shape[1] > 1 else block[:, 0])
    except sf.LibsndfileError as exc:
        raise FacegenError(
            f"cannot read {name} as audio ({exc.error_string if hasattr(exc, 'error_string') else exc}): "
            f"{fix}"
        ) from exc
    except (OSError, RuntimeError, TypeError) as exc:
        raise FacegenError(f"cannot read {name} as audio ({exc}): {fix}") from exc
    samples = np.concatenate(blocks) if blocks else np.zeros(0, np.float32)
    samples = np.ascontiguousarray(samples, dtype=np.float32)
    if not np.isfinite(samples).all():
        raise FacegenError(f"audio {name} contains NaN or infinite samples: re-export it")
    return samples, int(sr)


def write_wav(samples: np.ndarray, sample_rate: int, path: str | os.PathLike,
              subtype: str = "PCM_16") -> Path:
    """Write mono audio as a WAV file (16-bit PCM by default, samples clipped to [-1, 1]; "FLOAT" keeps
    them as they are). The one place audio is written; callers that need atomicity pass a temporary path."""
    import soundfile as sf

    samples = np.asarray(samples, dtype=np.float32).reshape(-1)
    if subtype.startswith("PCM"):
        samples = np.clip(samples, -1.0, 1.0)
    sf.write(str(path), samples, int(sample_rate), subtype=subtype, format="WAV")
    return Path(path)


def resample(samples: np.ndarray, orig_sr: int, target_sr: int) -> np.ndarray:
    """Resample with soxr (librosa's default resampler), float32 out."""
    if orig_sr == target_sr:
        return samples.astype(np.float32, copy=False)
    import soxr

    return soxr.resample(samples, orig_sr, target_sr, quality="HQ").astype(np.float32)


def num_frames(duration: float, fps: float) -> int:
    """The number of animation frames of a clip: round(duration * fps)."""
    return round(duration * fps)


SILENT_PEAK = 1e-4  # -80 dBFS: audio whose peak stays below this holds no speech


def is_silent(samples: np.ndarray) -> bool:
    """Whether `samples` peak below -80 dBFS (no speech to align or hear)."""
    return len(samples) == 0 or float(np.max(np.abs(samples))) < SILENT_PEAK


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


def mel_features(
    samples: np.ndarray, sr: int, cfg: FeatureConfig, filters: np.ndarray | None = None
) -> np.ndarray:
    """Mel power spectrogram in dB, [T, n_mels] float32 with T = round(duration * fps)."""
    import torch

    if filters is None:
        filters = mel_filters(cfg)
    y = resample(samples, sr, cfg.sample_rate)
    T = num_frames(len(samples) / sr, cfg.fps)
    hop = cfg.hop_length
    with torch.inference_mode():
        wav = torch.from_numpy(np.ascontiguousarray(y))
        pad = cfg.n_fft // 2
        if len(wav) <= pad:  # torch's padding needs more samples than the pad
            wav = torch.nn.functional.pad(wav, (0, pad + 1 - len(wav)))
        spec = torch.stft(
            wav,
            n_fft=cfg.n_fft,
            hop_length=hop,
            window=torch.hann_window(cfg.n_fft),
            center=True,
            pad_mode="constant",
            return_complex=True,
        )
        power = spec.real.square() + spec.imag.square()  # [F, frames]
        mel = torch.from_numpy(filters) @ power  # [n_mels, frames]
        db = 10.0 * torch.log10(torch.clamp(mel, min=cfg.amin))
    feats = db.T.numpy()
    if feats.shape[0] >= T:
        feats = feats[:T]
    else:  # can only be short by a frame or so: repeat the last one
        feats = np.concatenate([feats, np.repeat(feats[-1:], T - feats.shape[0], axis=0)])
    return np.ascontiguousarray(feats, dtype=np.float32)
