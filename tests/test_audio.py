import numpy as np
import pytest
import soundfile as sf

from facegen.audio import FeatureConfig, check_speech, load_audio, mel_features, mel_filters, num_frames
from facegen.errors import FacegenError

CFG = FeatureConfig()


def tone(sr: float, seconds: float, freq: float = 440.0) -> np.ndarray:
    t = np.arange(int(sr * seconds)) / sr
    return (0.3 * np.sin(2 * np.pi * freq * t)).astype(np.float32)


@pytest.mark.parametrize("fmt,subtype,sr,channels", [
    ("wav", "PCM_16", 44100, 2), ("wav", "PCM_24", 48000, 1), ("wav", "FLOAT", 22050, 1),
    ("flac", "PCM_16", 16000, 2), ("ogg", "VORBIS", 32000, 1), ("mp3", "MPEG_LAYER_III", 44100, 1),
])
def test_load_any_format_rate_and_channels(tmp_path, fmt, subtype, sr, channels):
    y = tone(sr, 1.2)
    data = np.stack([y] * channels, 1) if channels > 1 else y
    path = tmp_path / f"a.{fmt}"
    sf.write(path, data, sr, subtype=subtype, format=fmt.upper() if fmt != "mp3" else "MP3")
    samples, rate = load_audio(path)
    assert rate == sr and samples.ndim == 1 and samples.dtype == np.float32
    assert abs(len(samples) / sr - 1.2) < 0.06  # mp3/ogg may pad a little
    assert 0.2 < np.abs(samples).max() < 0.4


def test_exact_frame_count_and_matches_librosa():
    import librosa

    for seconds in (0.05, 1.0, 2.345, 4.7):
        y = tone(16000, seconds, 300)
        f = mel_features(y, 16000, CFG)
        assert f.shape == (num_frames(seconds, 25), 128) == (round(seconds * 25), 128)
    y = np.random.default_rng(0).normal(0, 0.1, 16000 * 3).astype(np.float32)
    ours = mel_features(y, 16000, CFG, mel_filters(CFG))
    ref = librosa.power_to_db(
        librosa.feature.melspectrogram(y=y, sr=16000, n_fft=2048, hop_length=640, n_mels=128, power=2.0),
        ref=1.0, amin=1e-10, top_db=None).T[:75]
    assert np.abs(ours - ref).max() < 1e-3


def test_resampling_keeps_the_spectrum():
    a = mel_features(tone(44100, 2.0, 1000), 44100, CFG)
    b = mel_features(tone(16000, 2.0, 1000), 16000, CFG)
    assert a.shape == b.shape == (50, 128)
    peak_band = mel_features(tone(16000, 2.0, 1000), 16000, CFG)[25].argmax()
    assert a[25].argmax() == peak_band
    assert np.abs(a[5:-5] - b[5:-5]).max() < 1.0  # dB


@pytest.mark.parametrize("content,msg", [(b"", "cannot read"), (b"not audio at all" * 100, "cannot read")])
def test_non_audio_files_are_refused(tmp_path, content, msg):
    p = tmp_path / "x.wav"
    p.write_bytes(content)
    with pytest.raises(FacegenError, match=msg):
        load_audio(p)


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(FacegenError, match="does not exist"):
        load_audio(tmp_path / "nope.wav")
    with pytest.raises(FacegenError, match="not a file"):
        load_audio(tmp_path)


def test_silent_and_too_short_audio_refused():
    with pytest.raises(FacegenError, match="silent"):
        check_speech(np.zeros(16000, np.float32), 16000, 25)
    with pytest.raises(FacegenError, match="shorter than one frame"):
        check_speech(tone(16000, 0.01), 16000, 25)
    check_speech(tone(16000, 0.5), 16000, 25)


def test_fps_must_divide_sample_rate():
    with pytest.raises(FacegenError, match="fps"):
        _ = FeatureConfig(fps=29.97).hop_length
