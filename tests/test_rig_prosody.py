"""The rig's articulation follows the audio's prosody and reads CMU phones as well as espeak's."""

from __future__ import annotations

import numpy as np
import pytest

from facegen.errors import FacegenError
from facegen.face.rig import LOWER_CHANNELS
from facegen.phonetics import phone_stress, phone_visemes
from facegen.synth.curves import loudness_envelope, viseme_curves

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
    for curves in (plain, prosody):  # the bilabials close the lips whatever the loudness
        assert curves[round(0.14 * 25), CLOSE] == 1.0 and curves[round(0.54 * 25), CLOSE] == 1.0
