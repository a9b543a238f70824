"""facegen.synth.voices: every installed Flite and Festival voice says a sentence with its own phone and word
timings; rate control; the errors a user meets (engine or voice not installed, unknown voice, nothing to
say)."""

from __future__ import annotations

import functools
import shutil

import numpy as np
import pytest

from facegen.errors import FacegenError
from facegen.synth import voices as V

SENTENCE = "Please open the window"
PHONES = ["P", "L", "IY", "Z", "OW", "P", "AH", "N", "DH", "AH", "W", "IH", "N", "D", "OW"]


@functools.cache
def _installed_ids(engine: str) -> frozenset[str]:
    return frozenset(V.ENGINES[engine].installed_ids())


def _installed(name: str) -> V.Voice:
    voice = V.VOICES[name]
    engine = V.ENGINES[voice.engine]
    if engine.binary and shutil.which(engine.binary) is None:
        pytest.skip(f"{engine.name} is not installed (make voices, or: {engine.install})")
    if voice.id not in _installed_ids(voice.engine):
        pytest.skip(f"{name} is not installed (make voices, or: apt-get install {voice.package})")
    return voice


def _envelope_db(audio: np.ndarray, sr: int) -> np.ndarray:
    """Level in dB per 10 ms frame."""
    hop = sr // 100
    frames = audio[: len(audio) // hop * hop].reshape(-1, hop).astype(np.float64)
    return 10 * np.log10(np.mean(frames**2, axis=1) + 1e-12)


ENGLISH = [name for name in V.VOICES if name.split("+")[0].split(":")[1][:2] == "en" or
           not name.startswith("espeak:")]


@pytest.mark.parametrize("name", ENGLISH)
def test_voice_says_a_sentence_with_its_timings(name):
    voice = _installed(name)
    utt = V.synthesize(SENTENCE, name)
    assert utt.voice == name
    assert utt.audio.dtype == np.float32 and utt.audio.ndim == 1
    native = 22050 if voice.engine == "espeak" else 16000
    assert utt.sample_rate == {"kal": 8000, "cmu_us_slt_arctic_hts": 32000}.get(voice.id, native)
    assert 0.8 <= utt.duration <= 3.0
    assert np.sqrt(np.mean(utt.audio**2)) > 0.01

    said = [p for p, _, _ in utt.phones]
    if utt.alphabet == "espeak":  # espeak's own mnemonics (the rig reads them); the same phones in CMU
        from facegen.phonetics import espeak_to_cmu

        said = espeak_to_cmu(said)
        # accents
        assert len(said) == len(PHONES) and sum(a != b for a, b in zip(said, PHONES, strict=True)) <= 1
    else:
        assert said == PHONES  # the engine's own phones, mapped to CMU
    starts, ends = np.array([s for _, s, _ in utt.phones]), np.array([e for _, _, e in utt.phones])
    assert np.all(ends > starts) and np.all(starts[1:] >= ends[:-1] - 1e-6)
    assert 0.0 <= starts[0] and ends[-1] <= utt.duration + 1e-3
    # the phones cover the speech: the sound above -30 dB (re the loudest 10 ms) lies inside their span
    db = _envelope_db(utt.audio, utt.sample_rate)
    loud = np.flatnonzero(db > db.max() - 30) / 100.0
    assert loud[0] >= starts[0] - 0.03 and loud[-1] <= ends[-1] + 0.1
    assert ends[-1] - starts[0] > 0.6 * (loud[-1] - loud[0])

    assert [w.lower() for w, _, _ in utt.words] == SENTENCE.lower().split()
    w_starts = [s for _, s, _ in utt.words]
    assert w_starts == sorted(w_starts)
    assert utt.words[-1][2] == pytest.approx(ends[-1], abs=0.03)
    assert utt.words[0][1] == pytest.approx(starts[0], abs=0.06 if voice.engine == "espeak" else 1e-6)
    assert all(e > s for _, s, e in utt.words)


@pytest.mark.parametrize("code", V.CORPUS_LANGUAGES)
def test_every_corpus_language_says_its_own_sentence(code):
    """One voice per language of the corpus (the six variants differ only in pitch and rate): its words
    in order, phones in CMU labelled from espeak-ng's IPA, inside the sound."""
    from facegen.synth.foreign_sentences import foreign_sentences

    name = f"espeak:{code}+{next(iter(V.FOREIGN_VARIANTS))}"
    _installed(name)
    sentence = foreign_sentences(code, 1, seed=3)[0]
    utt = V.synthesize(sentence, name)
    assert utt.alphabet == "cmu" and len(utt.phones) >= len(sentence.split())
    from facegen.phonetics import PHONES as CMU

    assert {p for p, _, _ in utt.phones} <= set(CMU)
    starts = np.array([s for _, s, _ in utt.phones])
    assert np.all(np.diff(starts) >= -1e-6) and utt.phones[-1][2] <= utt.duration + 1e-3
    assert [w.lower() for w, _, _ in utt.words] == [w.strip(".,?!") for w in sentence.lower().split()]
    assert [s for _, s, _ in utt.words] == sorted(s for _, s, _ in utt.words)


@pytest.mark.parametrize("name", ["flite:slt", "festival:kal_diphone", "festival:cmu_us_slt_arctic_hts"])
def test_rate_scales_the_durations(name):
    _installed(name)
    span = {}
    for rate in (1.0, 0.75):
        utt = V.synthesize(SENTENCE, name, rate=rate)
        span[rate] = utt.phones[-1][2] - utt.phones[0][1]
    assert span[0.75] / span[1.0] == pytest.approx(1 / 0.75, rel=0.1)


def test_flite_has_several_voices():
    flite = V.ENGINES["flite"]
    ids = flite.installed_ids()
    if not ids:
        pytest.skip(f"flite is not installed (make voices, or: {flite.install})")
    assert len([v for v in flite.voices if v.id in ids]) >= 3, ids
    assert {v.name for v in V.available_voices()} >= {v.name for v in flite.voices if v.id in ids}


def test_unknown_voice_lists_the_known_ones():
    with pytest.raises(FacegenError) as err:
        V.synthesize(SENTENCE, "flite:nobody")
    message = str(err.value)
    assert "flite:nobody" in message and "\n" not in message
    assert all(name in message for name in V.VOICES)


@pytest.mark.parametrize("name, package", [("flite:slt", "apt-get install flite"),
                                           ("festival:kal_diphone", "festvox-kallpc16k")])
def test_missing_engine_names_the_debian_package(name, package, monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(FacegenError, match=package) as err:
        V.synthesize(SENTENCE, name)
    assert "not installed" in str(err.value)
    assert {v.engine for v in V.available_voices()} <= {"espeak"}  # espeak is a library, not a program


@pytest.mark.parametrize("engine", ["flite", "festival"])
def test_voice_missing_from_an_installed_engine_names_its_package(engine):
    _installed(V.ENGINES[engine].voices[0].name)
    absent = V.Voice(engine, "no_such_voice", "female", f"{engine}-voice-pkg", "not installed anywhere")
    with pytest.raises(FacegenError, match=f"apt-get install {engine}-voice-pkg"):
        V.synthesize(SENTENCE, absent)


@pytest.mark.parametrize("text", ["", "   ", "?!", "..."])
def test_nothing_to_say_is_refused(text):
    with pytest.raises(FacegenError, match="nothing to say"):
        V.synthesize(text, "festival:kal_diphone")


def test_rate_out_of_range_is_refused():
    with pytest.raises(FacegenError, match="rate"):
        V.synthesize(SENTENCE, "flite:slt", rate=0.0)
