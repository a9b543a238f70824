"""facegen.phonetics: one table each (phone set, espeak -> CMU, CMU -> visemes, stress, vowels, silence)."""

from __future__ import annotations

import numpy as np
import pytest

from facegen.errors import FacegenError
from facegen.phonetics import (
    CMU_VISEMES,
    ESPEAK_TO_CMU,
    PHONES,
    SIL,
    VOWEL_VISEMES,
    check_alphabet,
    espeak_to_cmu,
    is_filler,
    is_pause,
    is_silence,
    phone_frames,
    phone_stress,
    phone_visemes,
    silence,
    to_cmu,
)


def test_phone_set_and_tables_agree():
    assert PHONES[0] == SIL and len(PHONES) == 40 and len(set(PHONES)) == 40
    assert all(p in PHONES for cmu in ESPEAK_TO_CMU.values() for p in cmu.split())  # espeak maps into the set
    assert all(p in CMU_VISEMES for p in PHONES[1:])  # every phone has visemes
    assert VOWEL_VISEMES == {"AA", "AE", "AH", "ER", "EH", "IY", "IH", "AO", "OW", "UH", "UW"}


def test_espeak_visemes_come_from_the_cmu_table():
    for name in ESPEAK_TO_CMU:
        assert phone_visemes(name) == tuple(v for p in espeak_to_cmu([name]) for v in CMU_VISEMES[p])
    assert phone_visemes("'a") == ("AE",) and phone_visemes("y") == ("UW",)  # the measured table's choices
    assert phone_visemes("aI@") == ("AA", "IH", "ER") and phone_visemes("_:") == ("rest",)


def test_espeak_to_cmu_strips_stress_and_merges_doubled_consonants():
    assert espeak_to_cmu(["h", "@", "l", "'oU"]) == ["HH", "AH", "L", "OW"]
    assert espeak_to_cmu(["b", "b", ",aI@"]) == ["B", "AY", "ER"]
    assert espeak_to_cmu(["_:", "qq"]) == []


def test_stress():
    assert phone_stress("'a") == 1.0 and phone_stress(",a") == 0.5 and phone_stress("a") is None
    assert phone_stress("AH0", "cmu") == 0.0 and phone_stress("EY2", "cmu") == 0.5
    assert phone_stress("K", "cmu") is None


def test_silence_labels():
    assert all(is_pause(x) for x in ("", "SIL", "sp", "<eps>", "pau", "h#", "{SL}"))
    assert not is_pause("hello") and not is_pause("_")
    assert is_filler("<sil>") and is_filler("+SPN+") and is_filler("[NOISE]") and not is_filler("sil")
    assert all(is_silence(x) for x in ("_", "_:", "SIL", "<s>", "+NSN+", "", "pau"))
    assert not any(is_silence(x) for x in ("a", "P", "AH1", "hello"))


def test_phone_frames():
    frames = phone_frames([("SIL", 0.0, 0.1), ("HH", 0.1, 0.2), ("AH0", 0.2, 0.4)], 12, 25.0)
    assert frames.shape == (12, len(PHONES)) and np.all(frames.sum(1) == 1)
    ids = frames.argmax(1)  # frame k sounds at k / 25 s
    assert [PHONES[i] for i in ids[[0, 3, 5, 9, 11]]] == ["SIL", "HH", "AH", "AH", "SIL"]
    spread = to_cmu([("aI@", 0.0, 0.3)], "espeak")  # one espeak phoneme, two CMU phones sharing its span
    assert [p for p, _, _ in spread] == ["AY", "ER"] and spread[1][1] == pytest.approx(0.15)
    assert np.array_equal(silence(3), phone_frames([], 3, 25.0))
    with pytest.raises(FacegenError, match="alphabet"):
        check_alphabet("ipa")
