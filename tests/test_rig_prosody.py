"""The rig's articulation follows the audio's prosody and reads CMU phones as well as espeak's."""

from __future__ import annotations

import numpy as np
import pytest

from facegen.errors import FacegenError
from facegen.face.rig import LOWER_CHANNELS
from facegen.phonetics import phone_stress, phone_visemes
from facegen.synth import curves
from facegen.synth.curves import formant_track, loudness_envelope, viseme_curves

JAW = LOWER_CHANNELS.index("jaw_open")
CLOSE = LOWER_CHANNELS.index("lip_close")
# "pa pa": two identical syllables, 0.4 s apart
CMU = [("P", 0.10, 0.18), ("AA1", 0.18, 0.40), ("P", 0.50, 0.58), ("AA1", 0.58, 0.80)]


def test_cmu_phones_map_to_the_same_visemes_as_espeak():
    assert phone_visemes("P", "cmu") == phone_visemes("p") == ("PBM",)
    assert phone_visemes("AY1", "cmu") == phone_visemes("aI") == ("AA", "IH")
    assert phone_visemes("SH", "cmu") == phone_visemes("S") == ("SH",)  # espeak's S is CMU's SH
    assert phone_visemes("SIL", "cmu") == ("rest",)
    assert phone_stress("AA1", "cmu") == 1.0 and phone_stress("AH0",
                                                              "cmu") == 0.0 and phone_stress("'a") == 1.0
    with pytest.raises(FacegenError, match="alphabet"):
        viseme_curves(CMU, 25, alphabet="ipa")


def test_louder_syllables_open_the_jaw_more_and_bilabials_still_close():
    rate, sr = 100.0, 16000
    t = np.arange(int(1.0 * sr)) / sr
    audio = np.sin(2 * np.pi * 150 * t) * np.where(t < 0.45, 0.05, 0.5)  # the second syllable is 20 dB louder
    loud = loudness_envelope(audio, sr, rate)
    assert loud.shape == (100,) and loud[70] - loud[30] == pytest.approx(20, abs=0.5)
    plain = viseme_curves(CMU, 25, 25.0, alphabet="cmu")
    prosody = viseme_curves(CMU, 25, 25.0, alphabet="cmu", loudness=loud, loudness_rate=rate)
    first, second = slice(5, 10), slice(15, 20)  # frames of the two vowels
    assert plain[first, JAW].max() == pytest.approx(plain[second, JAW].max(), rel=0.08)  # (the clip edge)
    assert prosody[second, JAW].max() > 1.3 * prosody[first, JAW].max()
    assert prosody[second, JAW].max() > plain[second, JAW].max() > prosody[first, JAW].max()
    for lower in (plain, prosody):  # the bilabials close the lips whatever the loudness
        assert lower[round(0.14 * 25), CLOSE] == 1.0 and lower[round(0.54 * 25), CLOSE] == 1.0


def _vowel(f1: float, f2: float, seconds: float, sr: int = 16000, pitch: float = 120.0) -> np.ndarray:
    """A vowel as a source-filter model makes it: a glottal pulse train through two formant resonators."""
    from scipy.signal import lfilter

    x = np.zeros(int(seconds * sr))
    x[::int(sr / pitch)] = 1.0
    for freq, bandwidth in ((f1, 80.0), (f2, 120.0)):
        r = np.exp(-np.pi * bandwidth / sr)
        x = lfilter([1.0], [1.0, -2 * r * np.cos(2 * np.pi * freq / sr), r * r], x)
    return 0.3 * x / np.abs(x).max()


@pytest.mark.parametrize(("f1", "f2"), [(730.0, 1090.0), (270.0, 2290.0), (530.0, 1840.0)])  # /a/, /i/, /e/
def test_formant_track_reads_a_vowels_first_formant(f1, f2):
    sr = 16000
    audio = np.concatenate([np.zeros(sr // 5), _vowel(f1, f2, 0.4, sr), np.zeros(sr // 5)])
    track = formant_track(audio, sr)
    assert track.shape == (80,)
    assert np.isnan(track[:15]).all() and np.isnan(track[-15:]).all()  # silence: no formant
    assert np.nanmedian(track[25:55]) == pytest.approx(f1, rel=0.15)  # LPC, with harmonics 120 Hz apart


def test_a_vowel_said_more_open_opens_the_jaw_more():
    """"pa pa" whose second /a/ has a higher first formant (900 against 600 Hz): its jaw opens more than the
    first's, by about the formants' ratio; equal formants leave the phones' curves as they are, and the
    bilabials close whatever the formants."""
    assert 0.5 <= curves.FORMANT_EXP <= 2.0 and curves.FORMANT_MAX >= 1.5  # docs/real_faces.md, ninth pass
    rate = 100.0
    t = np.arange(100) / rate
    plain = viseme_curves(CMU, 25, 25.0, alphabet="cmu")
    same = viseme_curves(CMU, 25, 25.0, alphabet="cmu", f1=np.full(100, 650.0), loudness_rate=rate)
    np.testing.assert_allclose(same, plain, atol=1e-6)
    f1 = np.where(t < 0.45, 600.0, 900.0).astype(np.float32)
    f1[(t > 0.4) & (t < 0.6)] = np.nan  # no formant in the /p/
    said = viseme_curves(CMU, 25, 25.0, alphabet="cmu", f1=f1, loudness_rate=rate)
    first, second = slice(5, 10), slice(15, 20)
    ratio = said[second, JAW].max() / said[first, JAW].max()
    assert 1.2 < ratio < 1.6, ratio
    lips = [c for c in range(len(LOWER_CHANNELS)) if c != JAW]
    np.testing.assert_allclose(said[:, lips], plain[:, lips], atol=1e-6)  # the formant moves the jaw only
    assert said[round(0.14 * 25), CLOSE] == 1.0 and said[round(0.54 * 25), CLOSE] == 1.0
