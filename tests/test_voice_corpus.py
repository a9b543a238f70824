"""The multi-voice corpus: voices drawn apart from styles, a held-out synthesiser, augmented audio, compact
rig curves that the dataset reader poses, phone timings whose p/b/m close the lips, resumable and refusing."""

from __future__ import annotations

import json

import numpy as np
import pytest

from facegen.audio import FeatureConfig, load_audio, mel_filters
from facegen.datasets.biwi import Dataset
from facegen.errors import FacegenError
from facegen.lipsync import FaceGeometry, aperture, bilabial_midpoints
from facegen.runtime import SILENT
from facegen.synth import voice_corpus as vc
from facegen.synth.voices import CORPUS_LANGUAGES, available_voices


def _engines() -> set[str]:
    return {v.engine for v in available_voices()}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    if not {"espeak", "flite", "festival"} <= _engines():
        pytest.skip("the voices corpus needs espeak-ng, Flite and Festival (make voices)")
    out = tmp_path_factory.mktemp("voices")
    manifest = vc.build(out, limit=1, workers=1, languages=LANGUAGES)
    return out, manifest


LANGUAGES = ("fr", "ru")


def test_plan_draws_voices_apart_from_styles_and_holds_out_flite():
    if not {"espeak", "flite", "festival"} <= _engines():
        pytest.skip("needs espeak-ng, Flite and Festival (make voices)")
    takes = vc.plan()
    assert len({t.sentence for t in takes if t.sentence < vc.XVOICE_OFFSET}) == 2400
    train = [t for t in takes if t.split == "train"]
    assert all(not t.voice.startswith("flite:") for t in takes if not t.split.endswith("xvoice"))
    assert {t.voice for t in takes if t.split.endswith("xvoice")} <= set(vc.TEST_VOICES)
    assert len({t.voice for t in train}) >= 18 and {t.subject for t in train} == set(vc.STYLES)
    # independence: every style hears many voices, every voice speaks for many styles
    pairs = {(t.subject, t.voice) for t in train}
    assert len(pairs) > 0.9 * len(vc.STYLES) * len({t.voice for t in train})
    assert vc.plan() == takes  # deterministic


def test_sequences_are_complete_and_consistent(corpus):
    out, manifest = corpus
    done = manifest["done"]
    assert {e["split"] for e in done.values()} == {"train", "val", "test", "test-unseen", "test-xvoice",
                                                    "test-unseen-xvoice", "train-fr", "val-fr", "test-fr",
                                                    "train-ru", "val-ru", "test-ru"}
    assert not [e for e in done.values() if "error" in e]
    for name, entry in done.items():
        audio, rate = load_audio(out / "wav" / f"{name}.wav")
        curves = np.load(out / "curves" / f"{name}.npy")
        assert rate == vc.RATE and curves.dtype == np.float32 and curves.shape == (entry["frames"], 12)
        assert entry["frames"] == round(len(audio) / rate * vc.FPS)
        align = json.loads((out / "alignments" / f"{name}.json").read_text())
        text = (out / "text" / f"{name}.txt").read_text().split()
        assert [w["word"] for w in align["words"]] == [t.strip(".,!?;:") for t in text]
        assert align["words"][-1]["end"] <= len(audio) / rate + 0.05
        meta = json.loads((out / "meta" / f"{name}.json").read_text())
        assert meta["voice"] == entry["voice"] and (meta["voice"].startswith("flite:")
                                                    == entry["split"].endswith("xvoice"))


def test_the_reader_poses_the_curves_and_bilabials_close_the_lips(corpus):
    out, manifest = corpus
    ds = Dataset(out, reporter=SILENT)
    seqs = ds.sequences(sorted(manifest["done"]))
    assert len(seqs) == len(manifest["done"]) and all(s.curves is not None for s in seqs)
    feats = FeatureConfig()
    items = ds.load(seqs, feats, mel_filters(feats), None)
    geo = FaceGeometry.of(ds.mesh)
    closed = total = 0
    for it in items:
        v = it.vertices().reshape(it.num_frames, -1, 3)
        assert np.abs(v - it.template).max() > 0.001  # it moves
        align = json.loads((out / "alignments" / f"{it.name}.json").read_text())
        mids = bilabial_midpoints([(p["phone"], p["start"], p["end"]) for p in align["phones"]], 25.0,
                                  align["alphabet"])
        ap = aperture(v, geo) * 10
        closed += int((ap[mids[mids < len(ap)]] < 1.0).sum())
        total += int((mids < len(ap)).sum())
        assert ap.max() > 5.0  # the mouth opens several mm
    assert total >= 3 and closed == total


def test_rerun_resumes_and_other_parameters_are_refused(corpus):
    out, manifest = corpus
    again = vc.build(out, limit=1, workers=1, languages=LANGUAGES)
    assert again["done"] == manifest["done"]
    with pytest.raises(FacegenError, match="other parameters"):
        vc.build(out, limit=2, workers=1, languages=LANGUAGES)
    with pytest.raises(FacegenError, match="other parameters"):
        vc.build(out, limit=1, workers=1, languages=("fr",))


def test_missing_voices_name_the_packages(monkeypatch, tmp_path):
    from facegen.synth import voices

    monkeypatch.setattr(voices, "available_voices", list)
    with pytest.raises(FacegenError, match="make voices"):
        vc.plan()


def test_phone_stream_trains_and_animates_from_the_transcripts_phones(corpus, tmp_path):
    """A model with the phone stream: trained on the corpus's phone timings; at inference its phones come
    from pocketsphinx's phone alignment of --text, or from an alignment file that lists them."""
    from facegen import animate
    from facegen.alignment_files import write_alignment
    from facegen.datasets.splits import Splits
    from facegen.train import train
    from facegen.train_config import TrainConfig
    from facegen.words import Word

    out, manifest = corpus
    train_names = [n for n, e in manifest["done"].items() if e["split"] in ("train", "val", "test")]
    numbers = ",".join(n.split("_e")[1] for n in train_names)
    splits = Splits(train_subjects=vc.STYLES, test_subjects=(), train_sentences=numbers, val_sentences="1",
                    test_sentences="2")
    small = {"conv_channels": 16, "audio_dim": 16, "text_hidden": 16, "text_dim_out": 8, "decoder_dim": 16,
             "lstm_dim": 16}
    config = TrainConfig(modalities="audio", epochs=2, splits=splits, model_options=small, output="pca",
                         basis=8, phones=True)
    result = train(out, tmp_path / "phones.safetensors", config, device="cpu", threads=1,
                   reporter=SILENT)
    assert result.train_sequences == 3
    from facegen.bundle import load_bundle

    bundle = load_bundle(tmp_path / "phones.safetensors")
    assert bundle.config.n_phones == 40 and bundle.provenance["phones"]
    name = train_names[0]
    wav, text = out / "wav" / f"{name}.wav", (out / "text" / f"{name}.txt").read_text().strip()
    anim = animate(wav, text=text, bundle=bundle, speaker=0)
    assert anim.metadata["word_timing"] == "forced alignment" and np.isfinite(anim.vertices).all()
    # the same words without phones in the file: the phones aligned inside their times
    words = [Word(w["word"], w["start"], w["end"])
             for w in json.loads((out / "alignments" / f"{name}.json").read_text())["words"]]
    write_alignment(words, tmp_path / "words.json")
    from_words = animate(wav, alignment=tmp_path / "words.json", bundle=bundle, speaker=0)
    assert from_words.metadata["word_timing"] == "alignment file + phones aligned"
    assert from_words.vertices.shape == anim.vertices.shape and np.isfinite(from_words.vertices).all()
    audio_only = animate(wav, no_text=True, bundle=bundle, speaker=0)  # phones of the recognised words
    assert audio_only.metadata["word_timing"] == "none (--no-text)"
    assert audio_only.vertices.shape == anim.vertices.shape and np.isfinite(audio_only.vertices).all()


def test_other_languages_are_planned_apart_and_never_the_held_out_ones():
    """20 languages of 9 families, 60 sentences each in three sentence ranges (one per split), each said by
    one of the language's espeak-ng voices; nl, pl and tr never."""
    if "espeak" not in _engines():
        pytest.skip("needs espeak-ng")
    from facegen.languages import HELD_OUT, check_language

    takes = vc.foreign_takes(CORPUS_LANGUAGES)
    assert len(takes) == 20 * vc.PER_LANGUAGE and not set(HELD_OUT) & set(CORPUS_LANGUAGES)
    assert len({check_language(c).family for c in CORPUS_LANGUAGES}) >= 9
    for split, first in vc.FOREIGN_FIRST.items():
        numbers = [t.sentence for t in takes if t.split.startswith(split + "-")]
        assert min(numbers) >= first and max(numbers) < first + 10000
    assert len({t.sentence for t in takes}) == len(takes)
    assert {t.split for t in takes if t.voice.startswith("espeak:ru+")} == {"train-ru", "val-ru", "test-ru"}
    assert sum(t.split == "train-fr" for t in takes) == 48 and sum(t.split == "val-fr" for t in takes) == 6
    assert vc.foreign_takes(CORPUS_LANGUAGES) == takes  # deterministic
    with pytest.raises(FacegenError, match="no voices for 'nl'"):
        vc.foreign_takes(("nl",))


def test_foreign_sentences_are_words_of_their_language():
    pytest.importorskip("wordfreq")
    from facegen.languages import check_language, script_of
    from facegen.synth.foreign_sentences import WORDS, foreign_sentences

    for code in ("fr", "ru", "el", "hi", "vi"):
        sentences = foreign_sentences(code, 40)
        assert foreign_sentences(code, 40) == sentences and len(set(sentences)) == 40
        scripts = set(check_language(code).scripts)
        for sentence in sentences:
            words = sentence.rstrip(".?").replace(",", "").split()
            assert WORDS[0] <= len(words) <= WORDS[1]
            assert all(script_of(c) in scripts for w in words for c in w if c.isalpha())
            assert not any(c.isdigit() for c in sentence)
            assert not [w for w in words if len(w) == 1 and w.lower() in "bcdfghjklmnpqrstvwxz"]
    assert any("ς" in s for s in foreign_sentences("el", 40))  # final sigma restored
    # no emotional word, of English or of any lexicon of facegen.lexicons: those stay unseen in training
    from facegen.lexicons import lexicon
    from facegen.synth.lexicon import LEXICON

    drawn = {w.strip(".,?").lower() for code in ("fr", "es", "it", "pt", "de", "ru")
             for s in foreign_sentences(code, 300) for w in s.split()}
    assert "triste" in {w for code in ("fr", "es", "it", "pt") for w in lexicon(code)}
    assert not drawn & ({w.lower() for w in LEXICON} | {w for code in ("fr", "es", "it", "pt", "de", "ru")
                                                       for w in lexicon(code)})


def test_foreign_phones_are_labelled_from_the_ipa():
    """A French /y/ is a rounded UW, a Spanish or Russian b/m a bilabial, in the synthesiser's time."""
    if "espeak" not in _engines():
        pytest.skip("needs espeak-ng")
    from facegen.synth.voices import synthesize

    utt = synthesize("Tu bois du jus.", "espeak:fr+m1")
    assert utt.alphabet == "cmu" and [p for p, _, _ in utt.phones][:4] == ["T", "UW", "B", "W"]
    assert all(b > a for _, a, b in utt.phones) and utt.phones[-1][2] <= utt.duration + 0.01
    assert all(b1 <= a2 + 1e-6 for (_, _, b1), (_, a2, _) in zip(utt.phones, utt.phones[1:]))
    ru = synthesize("Мама мыла раму.", "espeak:ru+f2")
    assert [p for p, _, _ in ru.phones].count("M") == 4


def test_pauses_move_the_timings_with_the_silence_they_insert():
    """with_pauses: the speech's samples kept in order, silence exactly where it says, every word and phone
    moved by the silence before it (a phone ending at the cut stays), and the rig's in-breath (the lips
    parting before speech after a pause) in the motion of such a take."""
    from facegen.synth.curves import PRE_SPEECH_S, viseme_curves

    sr = 16000
    speech = np.random.default_rng(0).uniform(0.1, 1.0, 2 * sr).astype(np.float32)
    words = [("a", 0.0, 0.5), ("b", 0.6, 1.2), ("c", 1.3, 2.0)]
    phones = [("AH", 0.0, 0.5), ("B", 0.6, 0.7), ("IY", 0.7, 1.2), ("S", 1.3, 1.5), ("IY", 1.5, 2.0)]
    seen_pause = seen_lead = 0
    for seed in range(20):
        audio, w, p, info = vc.with_pauses(speech, sr, words, phones, np.random.default_rng(seed))
        lead, trail = info["lead_s"], info["trail_s"]
        pause = info.get("pause", {"at_s": 9.0, "s": 0.0})
        assert abs(len(audio) - len(speech) - (lead + trail + pause["s"]) * sr) <= 3  # info rounds to 0.1 ms
        assert np.array_equal(audio[audio != 0], speech)  # the speech, whole and in order
        for (_, s0, e0), (_, s1, e1) in zip(phones, p, strict=True):
            assert s1 == pytest.approx(s0 + lead + (pause["s"] if s0 >= pause["at_s"] else 0), abs=1e-4)
            assert e1 == pytest.approx(e0 + lead + (pause["s"] if e0 > pause["at_s"] else 0), abs=1e-4)
            assert audio[int(s1 * sr) + 5] != 0 and audio[int(e1 * sr) - 5] != 0  # still on the speech
        assert [x[0] for x in w] == ["a", "b", "c"] and w[0][1] == pytest.approx(lead, abs=1e-4)
        if "pause" in info:
            assert pause["at_s"] in (0.6, 1.3) and 0.3 <= pause["s"] <= 0.9
            gap = round(pause["at_s"] * sr) + round(lead * sr)
            assert not audio[gap + 2: gap + round(pause["s"] * sr) - 2].any()
            seen_pause += 1
        if lead >= PRE_SPEECH_S + 0.3:  # the jaw opens in the in-breath before the first sound, rests before
            jaw = viseme_curves(p, int(len(audio) / sr * 25), 25.0, alphabet="cmu")[:, 0]
            assert jaw[0] < 0.02 and jaw[int(lead * 25) - 2] > 0.1
            seen_lead += 1
    assert 3 <= seen_pause <= 17 and seen_lead >= 5  # drawn, not always


def test_a_takes_jaw_reads_its_vowels_formants(tmp_path):
    """The rig animates each take from its own audio's loudness and first formant (facegen.synth.curves): an
    unaugmented take's stored curves are the rig's curves with the formants of its audio, and differ from
    those without them in the jaw alone."""
    from facegen.face.rig import LOWER_CHANNELS
    from facegen.synth.corpus import speaker_index
    from facegen.synth.curves import SpeakerStyle, formant_track, loudness_envelope, viseme_curves

    if "espeak" not in _engines():
        pytest.skip("needs espeak-ng (make voices)")
    take = next(t for t in vc.plan() if t.split == "train" and t.voice.startswith("espeak:en"))
    vc.make_take(take, tmp_path, augmentation=False)
    audio, rate = load_audio(tmp_path / "wav" / f"{take.name}.wav")
    stored = np.load(tmp_path / "curves" / f"{take.name}.npy")[:, :len(LOWER_CHANNELS)]
    align = json.loads((tmp_path / "alignments" / f"{take.name}.json").read_text())
    phones = [(p["phone"], p["start"], p["end"]) for p in align["phones"]]
    style = SpeakerStyle.for_speaker(speaker_index(take.subject))
    loud = loudness_envelope(audio, rate)
    heard = viseme_curves(phones, len(stored), vc.FPS, style, alphabet=align["alphabet"], loudness=loud,
                          f1=formant_track(audio, rate))
    plain = viseme_curves(phones, len(stored), vc.FPS, style, alphabet=align["alphabet"], loudness=loud)
    jaw = LOWER_CHANNELS.index("jaw_open")
    assert np.abs(stored - heard).max() < 0.02  # (the stored WAV is 16-bit)
    assert np.abs(stored[:, jaw] - plain[:, jaw]).max() > 0.05
    others = [c for c in range(len(LOWER_CHANNELS)) if c != jaw]
    np.testing.assert_allclose(stored[:, others], plain[:, others], atol=0.02)
