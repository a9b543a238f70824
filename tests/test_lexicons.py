"""Other languages' emotional words reach the text encoder as English glosses (facegen.lexicons, issue 25):
the lexicons' contents, the lookup, and the upper face's answer to a French emotional word on real audio."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from facegen.lexicons import LANGUAGES, glossed, lexicon
from facegen.synth.lexicon import TRAIN_LEXICON


def test_five_languages_or_more_each_glossed_by_training_words():
    assert len(LANGUAGES) >= 5
    for code in LANGUAGES:
        words = lexicon(code)
        assert len(words) >= 50, code
        assert set(words.values()) <= set(TRAIN_LEXICON), code  # the model learned what these mean
        classes = {TRAIN_LEXICON[g].cls for g in words.values()}
        assert {"joy", "sadness", "anger", "fear", "surprise"} <= classes, code


def test_lookup_ignores_case_and_edge_punctuation_and_keeps_other_words():
    assert glossed(["Il", "était", "FURIEUX,", "hier."], "fr") == ["Il", "était", "furious", "hier."]
    assert glossed(["Ich", "bin", "glücklich!"], "de") == ["Ich", "bin", "happy"]
    assert glossed(["feliz"], "pt-BR") == ["happy"]  # a regional code reads its language's lexicon
    assert glossed(["furieux"], "en") == ["furieux"] and glossed(["furieux"], None) == ["furieux"]
    assert glossed(["furieux"], "nl") == ["furieux"]  # no lexicon: as written


def test_a_glossed_word_reads_like_its_english_gloss():
    """The French sentence's "furieux" vector, glossed, lies nearer the English sentence's "furious" than the
    vector of "furieux" as written does (MiniLM's contextual states)."""
    from facegen.text import load_text_backend

    backend = load_text_backend()
    english = backend.word_vectors(["my", "brother", "was", "really", "furious", "last", "night"])[4]
    french = ["mon", "frère", "était", "vraiment", "furieux", "hier", "soir"]
    as_written = backend.word_vectors(french)[4]
    read = backend.word_vectors(glossed(french, "fr"))[4]

    def cos(a, b):
        return float(a @ b / np.linalg.norm(a) / np.linalg.norm(b))

    assert cos(read, english) > cos(as_written, english) + 0.2


@pytest.mark.parametrize("language, frame, word, neutral", [
    ("fr", "Mon frère était vraiment {} hier soir.", "furieux", "grand"),
    ("de", "Mein Bruder war gestern Abend wirklich {}.", "wütend", "groß"),
])
def test_the_upper_face_answers_an_emotional_word_in_another_language(tmp_path, language, frame, word,
                                                                     neutral):
    """Same audio and word times: the upper face moves at least 1.5x more with the emotional word than with a
    neutral one in its place (issue 25's target), and more than with the word as written."""
    from facegen.animator import Animator
    from facegen.audio import write_wav
    from facegen.espeak import synthesize
    from facegen.languages import check_language
    from facegen.lipsync import FaceGeometry, upper_face_response
    from facegen.text import text_features
    from facegen.words import Word

    said = synthesize(frame.format(word), voice=check_language(language).voice, sample_rate=16000)
    pad = np.zeros(4800, np.float32)
    wav = write_wav(np.concatenate([pad, said.audio, pad]), 16000, tmp_path / "line.wav")
    animator = Animator(None)
    clip = animator.prepare(wav, text=frame.format(word), language=language, speaker=0)
    rest, bundle = clip.mesh.vertices, animator.bundle

    def face(words, lang):
        feats = text_features(words, animator.text_backend(), clip.num_frames, bundle.features, lang)
        return rest + animator.offsets(replace(clip, text_features=feats))

    calm = face([Word(t.strip("."), w.start, w.end) for t, w in
                 zip(frame.format(neutral).split(), clip.words, strict=True)], language)
    geo = FaceGeometry.of(bundle.template)
    response = upper_face_response(calm, rest + animator.offsets(clip), geo, rest_pose=rest)
    as_written = upper_face_response(calm, face(clip.words, None), geo, rest_pose=rest)
    assert response >= 1.5 and response > as_written, (response, as_written)


def test_a_glossed_word_is_read_in_an_english_phrase_and_the_rest_in_the_sentence():
    from facegen.text import GLOSS_CARRIER, language_word_vectors, load_text_backend

    backend = load_text_backend()
    french = ["Il", "était", "furieux", "hier"]
    read = language_word_vectors(backend, french, "fr")
    phrase = GLOSS_CARRIER.format("furious").split()
    np.testing.assert_allclose(read[2], backend.word_vectors(phrase)[phrase.index("furious")], atol=1e-5)
    in_sentence = backend.word_vectors(["Il", "était", "furious", "hier"])
    np.testing.assert_allclose(read[[0, 1, 3]], in_sentence[[0, 1, 3]], atol=1e-5)
    english = ["He", "was", "furious"]
    np.testing.assert_allclose(language_word_vectors(backend, english, None), backend.word_vectors(english))
    assert language_word_vectors(backend, [], "fr").shape == (0, backend.dim)
