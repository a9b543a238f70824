"""facegen.synth.augment: each step measured (SNR, reverberation decay, band edges, codec alignment, tempo
time scale, level, pitch and formant shifts) and the random chain deterministic for a seed."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import correlate, welch

from facegen.synth import augment as A

SR = 16000


def _speechlike(seconds: float = 2.0, f0: float = 140.0, seed: int = 0) -> np.ndarray:
    """Harmonics of f0 under a falling spectral tilt, gated into 'syllables' with silences between and
    around."""
    t = np.arange(int(seconds * SR)) / SR
    voiced = sum(np.sin(2 * np.pi * k * f0 * t + k) / k for k in range(1, 25))
    gate = ((t > 0.3) & (t < seconds - 0.3)) * (np.sin(2 * np.pi * 3.0 * t) > -0.2)
    noise = 0.05 * np.random.default_rng(seed).standard_normal(len(t))
    return (0.1 * (voiced + noise) * gate).astype(np.float32)


def _bursts(seconds: float = 2.0) -> np.ndarray:
    """Noise bursts at known times (0.5 s, 1.2 s), silence elsewhere: a signal whose timing is unambiguous."""
    x = np.zeros(int(seconds * SR), np.float32)
    rng = np.random.default_rng(3)
    for start in (0.5, 1.2):
        i = int(start * SR)
        x[i: i + SR // 10] = 0.3 * rng.standard_normal(SR // 10)
    return x


def _lag(y: np.ndarray, x: np.ndarray) -> int:
    corr = correlate(y, x, mode="full", method="fft")
    return int(np.argmax(corr)) - (len(x) - 1)


def _onset(x: np.ndarray) -> float:
    """Seconds to the first 5 ms frame within 20 dB of the loudest."""
    hop = SR // 200
    e = 10 * np.log10(np.mean(x[: len(x) // hop * hop].reshape(-1, hop).astype(np.float64) ** 2, 1) + 1e-15)
    return np.argmax(e > e.max() - 20) / 200


@pytest.mark.parametrize("kind", A.NOISE_KINDS)
@pytest.mark.parametrize("snr", [5.0, 17.0, 30.0])
def test_noise_lands_on_the_asked_snr(kind, snr):
    x = _speechlike()
    y = A.add_noise(x, snr, A.make_noise(x, kind, np.random.default_rng(0)))
    measured = 10 * np.log10(np.sum(x.astype(np.float64) ** 2) / np.sum((y - x).astype(np.float64) ** 2))
    assert measured == pytest.approx(snr, abs=1.0)


def test_pink_noise_falls_with_frequency():
    n = A.make_noise(np.zeros(4 * SR, np.float32), "pink", np.random.default_rng(0))
    f, p = welch(n, SR, nperseg=4096)
    low, high = p[(f > 100) & (f < 200)].mean(), p[(f > 3200) & (f < 6400)].mean()
    # 1/f: ~15 dB over 5 octaves
    assert 10 * np.log10(low / high) == pytest.approx(10 * np.log10(32), abs=2.0)


@pytest.mark.parametrize("rt60", [0.2, 0.5, 0.8])
def test_reverb_decays_at_the_asked_rt60(rt60):
    ir = A.room_impulse_response(SR, rt60, 5.0, np.random.default_rng(0))
    assert ir[0] == 1.0  # direct path at lag 0: timings stay
    edc = np.cumsum((ir**2)[::-1])[::-1]
    edc_db = 10 * np.log10(edc / edc[0])
    t5, t25 = np.argmax(edc_db < -5) / SR, np.argmax(edc_db < -25) / SR
    assert 3 * (t25 - t5) == pytest.approx(rt60, rel=0.1)  # T20 extrapolated to 60 dB

    dry = _bursts()
    wet = A.reverb(dry, ir)
    assert len(wet) == len(dry)
    assert np.sqrt(np.mean(wet**2)) == pytest.approx(np.sqrt(np.mean(dry**2)), rel=1e-3)

    def decay(x):  # seconds after the first burst ends until the level is 20 dB below the burst's
        hop = SR // 200
        e = 10 * np.log10(np.mean(x[: len(x) // hop * hop].reshape(-1, hop).astype(np.float64) ** 2, 1)
                          + 1e-15)
        ref, end = e[int(0.55 * 200): int(0.59 * 200)].mean(), int(0.6 * 200)
        return np.argmax(e[end:] < ref - 20) / 200

    assert decay(dry) <= 0.01
    assert decay(wet) > 0.15 * rt60


def _band_change_db(x, y, lo, hi):
    f, px = welch(x, SR, nperseg=2048)
    _, py = welch(y, SR, nperseg=2048)
    m = (f >= lo) & (f < hi)
    return 10 * np.log10(py[m].sum() / px[m].sum())


def test_telephone_band_removes_what_lies_outside_300_3400_hz():
    x = (0.1 * np.random.default_rng(1).standard_normal(4 * SR)).astype(np.float32)
    y = A.band_limit(x, SR, 300.0, 3400.0)
    assert abs(_band_change_db(x, y, 500, 3000)) < 0.5
    assert _band_change_db(x, y, 0, 300) < -15
    assert _band_change_db(x, y, 3400, 8000) < -15
    assert _band_change_db(x, y, 0, 200) < -35
    assert _band_change_db(x, y, 4000, 8000) < -35
    assert _lag(y, x) == 0  # zero phase


def test_lowpass_removes_what_lies_above_the_cutoff():
    x = (0.1 * np.random.default_rng(2).standard_normal(4 * SR)).astype(np.float32)
    y = A.band_limit(x, SR, None, 5000.0)
    assert abs(_band_change_db(x, y, 100, 4000)) < 0.5
    assert _band_change_db(x, y, 6000, 8000) < -35


@pytest.mark.parametrize("codec, setting", [("mp3", 32), ("mp3", 64), ("ogg", 0)])
def test_codec_round_trip_keeps_the_timing(codec, setting):
    x = _bursts() + 0.2 * _speechlike()
    y = A.codec_round_trip(x, SR, codec, setting)
    assert len(y) == len(x)
    assert abs(_lag(y, x)) <= 0.005 * SR
    err = np.sqrt(np.mean((y - x) ** 2) / np.mean(x**2))
    assert 1e-3 < err < 0.7  # lossy, but the same sound


@pytest.mark.parametrize("factor", [0.9, 1.1])
def test_tempo_returns_the_duration_ratio(factor):
    x = _bursts()
    y, scale = A.tempo(x, SR, factor)
    assert scale == len(y) / len(x)
    assert scale == pytest.approx(1 / factor, rel=0.01)
    assert _onset(y) == pytest.approx(_onset(x) * scale, abs=0.01)  # a time t moves to t * scale


@pytest.mark.parametrize("dbfs", [-35.0, -20.0, -10.0])
def test_level_lands_on_the_target(dbfs):
    x = _speechlike() + _bursts()  # crest factor high enough that -10 dBFS needs the soft knee
    y = A.normalize_level(x, dbfs)
    assert A.rms_dbfs(y) == pytest.approx(dbfs, abs=0.5)
    assert np.abs(y).max() < 1.0


def test_pitch_shift_moves_f0_and_keeps_duration():
    t = np.arange(2 * SR) / SR
    tone = (0.3 * np.sin(2 * np.pi * 200.0 * t)).astype(np.float32)
    y = A.pitch_shift(tone, SR, 3.0)
    assert len(y) == len(tone)
    spectrum = np.abs(np.fft.rfft(y[SR // 2: 3 * SR // 2] * np.hanning(SR)))
    assert np.argmax(spectrum) == pytest.approx(200.0 * 2 ** (3 / 12), abs=2.0)  # 1 Hz bins


def test_formant_shift_moves_the_envelope_not_the_pitch():
    x = _speechlike()
    f, p = welch(x, SR, nperseg=2048)
    centroid = {}
    for factor in (0.9, 1.0, 1.1):
        y = A.formant_shift(x, SR, factor)
        assert len(y) == len(x)
        _, py = welch(y, SR, nperseg=2048)
        centroid[factor] = np.sum(f * py) / np.sum(py)
        assert f[np.argmax(py)] == pytest.approx(f[np.argmax(p)], abs=SR / 2048)  # F0 peak stays
    assert centroid[0.9] < centroid[1.0] < centroid[1.1]
    assert centroid[1.1] / centroid[1.0] == pytest.approx(1.1, abs=0.06)


ALL = A.AugmentSpec(p_pitch=1, p_formant=1, p_tempo=1, p_reverb=1, p_noise=1, p_band=1, p_codec=1, p_level=1)


def test_augment_is_deterministic_for_a_seed():
    x = _speechlike()
    a, scale_a, info_a = A.augment(x, SR, 7, ALL)
    b, scale_b, info_b = A.augment(x, SR, np.random.default_rng(7), ALL)
    c, _, info_c = A.augment(x, SR, 8, ALL)
    assert np.array_equal(a, b) and scale_a == scale_b and info_a == info_b
    assert info_c != info_a and not np.array_equal(a[: len(c)], c[: len(a)])
    assert set(info_a) == {"pitch_semitones", "formant_factor", "tempo_factor", "reverb", "noise", "band_hz",
                           "codec", "level_dbfs"}
    assert len(a) == round(len(x) * scale_a) and scale_a == pytest.approx(1 / info_a["tempo_factor"],
                                                                          rel=0.01)
    assert A.rms_dbfs(a) == pytest.approx(info_a["level_dbfs"], abs=0.5)
    assert a.dtype == np.float32 and np.isfinite(a).all()


def test_augment_with_nothing_drawn_returns_the_clip():
    none = A.AugmentSpec(p_pitch=0, p_formant=0, p_tempo=0, p_reverb=0, p_noise=0, p_band=0, p_codec=0,
                         p_level=0)
    x = _speechlike()
    y, scale, info = A.augment(x, SR, 0, none)
    assert np.array_equal(x, y) and scale == 1.0 and info == {}


def test_loudness_drift_declines_and_swells_slowly_within_its_limits():
    """The gain it lays on the speech: the drawn declination from start to end, swells of a few dB, no step
    faster than a syllable's, never beyond DRIFT_LIMIT_DB; the timing untouched; deterministic per seed."""
    x = _speechlike(4.0)
    declinations = []
    for seed in range(12):
        y, info = A.loudness_drift(x, SR, seed, p=1.0)
        assert info is not None and y.dtype == np.float32 and len(y) == len(x)
        assert A.DECLINATION_DB[0] <= info["declination_db"] <= A.DECLINATION_DB[1]
        assert len(info["swells_db"]) == 9  # one knot per 0.5 s over 4 s, both ends included
        on = np.abs(x) > 1e-3
        gain_db = 20 * np.log10(np.abs(y[on]) / np.abs(x[on]))
        assert np.abs(gain_db).max() <= A.DRIFT_LIMIT_DB + 1e-3
        t = np.flatnonzero(on) / SR
        step = np.abs(np.diff(np.interp(np.arange(0.35, 3.65, 0.01), t, gain_db)))
        assert step.max() < 1.0  # dB per 10 ms: slow, a loudness contour rather than a tremolo
        # at the knots (every 0.5 s) the gain is the declination's ramp plus that knot's swell
        swells = np.asarray(info["swells_db"])
        at = np.interp([0.5, 3.5], t, gain_db) - swells[[1, 7]]
        assert at[1] - at[0] == pytest.approx(info["declination_db"] * 3 / 4, abs=0.1)
        declinations.append(info["declination_db"])
        assert np.corrcoef(np.abs(y), np.abs(x))[0, 1] > 0.8  # the same sound, only louder or softer
    assert min(declinations) < -5 and max(declinations) > -2  # drawn over the range
    a, info_a = A.loudness_drift(x, SR, np.random.default_rng(3), p=1.0)
    b, info_b = A.loudness_drift(x, SR, 3, p=1.0)
    assert np.array_equal(a, b) and info_a == info_b
    kept, none = A.loudness_drift(x, SR, 3, p=0.0)
    assert none is None and np.array_equal(kept, x)
