"""The synthetic speech-and-motion corpus: layout, timing, lips, upper face, sentences, determinism."""

from __future__ import annotations

import json

import numpy as np
import pytest
import soundfile as sf

from facegen.datasets.biwi import Dataset
from facegen.datasets.splits import Splits, sequence_name
from facegen.errors import FacegenError
from facegen.face.procedural import NUM_VERTICES
from facegen.face.rig import CHANNELS
from facegen.phonetics import VOWEL_VISEMES, phone_visemes
from facegen.synth import corpus
from facegen.synth.lexicon import HELD_OUT_LEXICON, TRAIN_LEXICON, emotional_words
from facegen.synth.sentences import SENTENCES

SPEAKERS = ("F2", "M1")
NUMBERS = (1, 7)  # e01 has "amazed" (surprise), e07 no emotional word
NAMES = [sequence_name(s, n) for s in SPEAKERS for n in NUMBERS]


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    root = tmp_path_factory.mktemp("synth")
    report = corpus.synthesize_corpus(root, ",".join(SPEAKERS), "1,7", workers=2)
    return root, report


@pytest.fixture(scope="module")
def f2():
    """F2's rig and style, and e01 and e07 spoken and animated in this process."""
    rig, style = corpus.speaker_rig("F2")
    seqs = {}
    for n in NUMBERS:
        speech = corpus.speak("F2", n)
        seqs[n] = (speech, corpus.motion(speech, rig, style, corpus.sequence_rng(0, "F2", n)))
    return rig, seqs


def test_layout_loads_with_dataset(small):
    root, report = small
    assert sorted(report.generated) == sorted(NAMES) and not report.present
    for name in NAMES:
        for sub, ext in (("wav", "wav"), ("vertices_npy", "npy"), ("text", "txt"), ("alignments", "json")):
            assert (root / sub / f"{name}.{ext}").is_file(), f"{sub}/{name}.{ext}"
    ds = Dataset(root)
    seqs = ds.sequences(NAMES)
    assert [s.name for s in seqs] == NAMES and not ds.skipped
    assert all(s.text is not None and s.alignment is not None for s in seqs)
    assert set(ds.templates) == set(SPEAKERS)
    assert all(t.shape == (NUM_VERTICES, 3) for t in ds.templates.values())
    assert ds.mesh.num_vertices == NUM_VERTICES
    assert {"lips", "upper_face", "jaw", "brows"} <= set(ds.mesh.regions)
    manifest = json.loads((root / corpus.MANIFEST).read_text())
    assert sorted(manifest["sequences"]) == sorted(NAMES)
    assert manifest["params"] == corpus.parameters(0, 25.0)
    assert (root / "text" / "F2_e01.txt").read_text().strip() == SENTENCES[1]


def test_frames_match_audio_duration(small):
    root, _ = small
    durations = []
    for name in NAMES:
        audio, sr = sf.read(root / "wav" / f"{name}.wav")
        v = np.load(root / "vertices_npy" / f"{name}.npy")
        assert v.dtype == np.float32 and v.shape[1] == 3 * NUM_VERTICES
        assert v.shape[0] == round(len(audio) / sr * 25)
        duration = len(audio) / sr
        durations.append(duration)
        words = json.loads((root / "alignments" / f"{name}.json").read_text())["words"]
        number = int(name.split("_e")[1])
        assert [w["word"] for w in words] == [t.strip(",.?!") for t in SENTENCES[number].split()]
        assert words[-1]["end"] <= duration + 1e-3 and all(w["start"] < w["end"] for w in words)
    assert 3.0 < np.mean(durations) < 6.5


def test_speakers_differ(small):
    root, _ = small
    ds = Dataset(root)
    shape = np.abs(ds.templates["F2"] - ds.templates["M1"]).mean()
    assert shape > 1e-3
    a = np.load(root / "vertices_npy" / "F2_e07.npy")
    b = np.load(root / "vertices_npy" / "M1_e07.npy")
    assert a.shape != b.shape or np.abs(a - b).mean() > 1e-3  # other voice (timing) and other face
    wav_a, _ = sf.read(root / "wav" / "F2_e07.wav")
    wav_b, _ = sf.read(root / "wav" / "M1_e07.wav")
    assert len(wav_a) != len(wav_b)


def _lip_gap(vertices: np.ndarray, regions: dict, cm: float) -> np.ndarray:
    """Per frame: the mean distance (cm) between the upper and lower lip margins at the mouth's centre."""
    mu, ml = regions["mouth_upper_margin"], regions["mouth_lower_margin"]
    mid = slice(len(mu) // 2 - 3, len(mu) // 2 + 4)
    return np.linalg.norm(vertices[:, mu[mid]] - vertices[:, ml[mid]], axis=2).mean(1) / cm


def test_lips_close_on_bilabials_and_open_on_vowels(small, f2):
    root, _ = small
    regions = Dataset(root).regions
    rig, seqs = f2
    closed, opened = [], []
    for speech, v in seqs.values():
        gap = _lip_gap(v, regions, rig.cm)
        t = np.arange(len(v)) / 25
        for p in speech.phones:
            frames = np.nonzero((t >= p.start) & (t <= p.end))[0]
            vis = phone_visemes(p.text)
            if vis == ("PBM",):
                closed += list(gap[frames])
            elif vis[0] in VOWEL_VISEMES and vis[0] in ("AA", "AE", "EH") and p.end - p.start > 0.06:
                # inside the vowel, 20 ms from its edges: libespeak-ng's phone times move by up to a pitch
                # period (~10 ms) with state left by earlier calls, which puts a frame of the transition in
                inner = np.nonzero((t >= p.start + 0.02) & (t <= p.end - 0.02))[0]
                opened += list(gap[inner])
    assert len(closed) >= 6 and len(opened) >= 10
    assert max(closed) < 0.02  # cm: the lips meet
    assert np.median(opened) > 0.5 and min(opened) > 0.15  # cm: the mouth is open


def _still_upper(rig, regions) -> np.ndarray:
    """Upper-face vertices that a blink does not move."""
    blink = np.zeros((1, len(CHANNELS)), np.float32)
    blink[0, CHANNELS.index("blink")] = 1.0
    moved = np.linalg.norm(rig.pose(blink)[0] - rig.template, axis=1) > 1e-6
    upper = regions["upper_face"]
    return upper[~moved[upper]]


def test_upper_face_moves_only_with_emotional_words(small, f2):
    root, _ = small
    regions = Dataset(root).regions
    rig, seqs = f2
    keep = _still_upper(rig, regions)
    assert len(keep) > 0.5 * len(regions["upper_face"])

    def displacement(v: np.ndarray) -> np.ndarray:  # per frame, max over the kept vertices, cm
        return np.linalg.norm(v[:, keep] - rig.template[keep][None], axis=2).max(1) / rig.cm

    speech, v = seqs[1]
    assert emotional_words(SENTENCES[1]) == ["amazed"]
    word = next(w for w in speech.words if w.text == "amazed")
    d = displacement(v)
    t = np.arange(len(v)) / 25
    assert d[t < word.start].max() < 1e-4  # still before the word
    assert d[(t >= word.start) & (t <= word.end + 0.3)].max() > 0.2  # brows raised around it
    assert d[t > word.end + 2.0].max() < 1e-4  # and back at rest after the decay

    speech, v = seqs[7]
    assert emotional_words(SENTENCES[7]) == []
    assert displacement(v).max() < 1e-4  # a neutral sentence: only the mouth (and blinks) move


def test_sentences_keep_held_out_words_out_of_training():
    for n in range(1, 41):
        assert emotional_words(SENTENCES[n], HELD_OUT_LEXICON) == [], f"e{n:02d}"
    for n in range(41, 49):
        held = emotional_words(SENTENCES[n], HELD_OUT_LEXICON)
        assert 1 <= len(held) <= 2 and emotional_words(SENTENCES[n], TRAIN_LEXICON) == [], f"e{n:02d}"
    with_words = [n for n in range(1, 41) if emotional_words(SENTENCES[n], TRAIN_LEXICON)]
    assert 30 <= len(with_words) < 40  # most, not all
    assert all(emotional_words(SENTENCES[n], TRAIN_LEXICON) for n in range(33, 40))
    classes = {TRAIN_LEXICON[w].cls for n in with_words for w in emotional_words(SENTENCES[n], TRAIN_LEXICON)}
    assert classes == {"surprise", "anger", "sadness", "fear", "awe", "joy"}


def test_deterministic_and_independent_of_what_else_is_generated(small, tmp_path):
    root, _ = small
    report = corpus.synthesize_corpus(tmp_path, "F2", "7")  # alone, not after e01
    assert report.generated == ["F2_e07"]
    for sub, ext in (("wav", "wav"), ("vertices_npy", "npy"), ("alignments", "json"), ("text", "txt")):
        a = (root / sub / f"F2_e07.{ext}").read_bytes()
        assert a == (tmp_path / sub / f"F2_e07.{ext}").read_bytes(), sub


def test_resume_skips_and_other_parameters_are_refused(small):
    root, _ = small
    again = corpus.synthesize_corpus(root, ",".join(SPEAKERS), "1,7")
    assert again.generated == [] and sorted(again.present) == sorted(NAMES)
    with pytest.raises(FacegenError, match="other parameters"):
        corpus.synthesize_corpus(root, "F2", "1", seed=1)


def test_selection_and_splits():
    paper = corpus.selection(preset="paper")
    assert sum(len(v) for v in paper.values()) == 6 * 48 + 8 * 12
    assert paper["F2"] == tuple(range(1, 49)) and paper["M6"] == tuple(range(37, 49))
    names = {sequence_name(s, n) for s, ns in paper.items() for n in ns}
    default, unseen = Splits(), Splits(test_sentences=range(41, 49))
    for splits in (default, unseen):
        for split in ("train", "val", "test-a", "test-b"):
            assert set(splits.names(split)) <= names
    assert len(unseen.names("test-b")) == 8 * 8 and len(unseen.names("test-a")) == 6 * 8
    assert corpus.selection("F1, M6", "1-3") == {"F1": (1, 2, 3), "M6": (1, 2, 3)}
    with pytest.raises(FacegenError, match="unknown synthetic speaker"):
        corpus.selection("F9")
    with pytest.raises(FacegenError, match="no sentence e49"):
        corpus.selection("F1", "48-49")
    with pytest.raises(FacegenError, match="preset"):
        corpus.selection("F1", preset="paper")
