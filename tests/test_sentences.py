"""The corpus's words: the lexicon (classes, roles, held-out words) and the generated sentences (e49 on)."""

import collections
import re

import pytest

from facegen.datasets.splits import sequence_name
from facegen.synth import sentences as S
from facegen.synth.lexicon import CLASSES, HELD_OUT_LEXICON, LEXICON, ROLES, TRAIN_LEXICON, emotional_words
from facegen.synth.sentences import (
    FIRST_GENERATED,
    SENTENCES,
    check_generated,
    generated_sentences,
    generated_splits,
    neutral_twin,
)

# the emotional words of e01-e48 before the lexicon grew: its new words must leave them (and the corpus) alone
HAND_WRITTEN = {
    1: ["amazed"], 2: ["furious"], 3: ["lonely"], 4: ["scared"], 5: ["breathtaking"], 6: ["delighted"], 7: [],
    8: ["shocking"], 9: ["annoyed"], 10: ["tragic", "mourning"], 11: ["dangerous"], 12: ["magnificent"],
    13: ["laughed"], 14: [], 15: ["suddenly", "unexpected"], 16: ["hate"], 17: ["sorry"],
    18: ["worried", "wonderful"], 19: ["vast", "glorious"], 20: ["thrilled"], 21: [], 22: ["incredible"],
    23: ["angry"], 24: ["miserable"], 25: ["horrible"], 26: ["spectacular", "laughing"],
    27: ["lovely", "happy"],
    28: [], 29: ["astonished"], 30: ["bitter"], 31: ["tears"], 32: ["terrified"], 33: ["surprised"],
    34: ["livid"], 35: ["gloomy"], 36: ["frightened", "sudden"], 37: ["marvelous"], 38: ["cheerful"],
    39: ["irritated", "anxious"], 40: [], 41: ["flabbergasted"], 42: ["seething"], 43: ["forlorn"],
    44: ["petrified"], 45: ["resplendent"], 46: ["jubilant"], 47: ["bewildered", "indignant"],
    48: ["elated", "stupendous"],
}


@pytest.fixture(scope="module")
def corpus():
    return generated_sentences(), generated_splits()


# ---------------------------------------------------------------------------------------------- lexicon
def test_lexicon_size_classes_roles_and_held_out_share():
    assert len(LEXICON) >= 400 and len(HELD_OUT_LEXICON) >= 60
    assert not set(TRAIN_LEXICON) & set(HELD_OUT_LEXICON)
    assert set(CLASSES) == {"surprise", "anger", "sadness", "fear", "awe", "joy"}
    for cls in CLASSES:
        every = [e for e in LEXICON.values() if e.cls == cls]
        held = [e for e in HELD_OUT_LEXICON.values() if e.cls == cls]
        assert len(every) >= 50 and len(held) >= 0.15 * len(every), cls
        intensities = sorted(e.intensity for e in held)
        assert intensities[0] <= 0.6 and intensities[-1] >= 0.9, f"{cls}: held-out intensities {intensities}"
        for table in (TRAIN_LEXICON, HELD_OUT_LEXICON):  # templates need both adjective roles in both
            roles = {e.role for e in table.values() if e.cls == cls}
            assert {"experiencer", "stimulus"} <= roles, cls
    for word, emotion in LEXICON.items():
        assert word.isalpha() and word.islower(), word  # one plain word espeak-ng reads (no hyphen or space)
        assert emotion.role in ROLES and 0 < emotion.intensity <= 1, word


def test_new_words_leave_the_hand_written_sentences_alone():
    assert {n: emotional_words(text) for n, text in SENTENCES.items()} == HAND_WRITTEN


def test_template_word_lists_hold_no_lexicon_word():
    assert not (set(S._NEUTRAL["experiencer"]) | set(S._NEUTRAL["stimulus"])) & set(LEXICON)
    assert all(LEXICON[w].role == "stimulus" for w in S._SCENIC)


# ---------------------------------------------------------------------------------------------- sentences
def test_generated_rules_counts_and_distinctness(corpus):
    sentences, splits = corpus
    check_generated()
    assert len(set(sentences.values())) >= 2000 and min(sentences) == FIRST_GENERATED == 49
    assert [len(splits[k]) for k in ("train", "val", "test", "test-unseen")] == [1728, 216, 216, 240]
    assert sorted(n for r in splits.values() for n in r) == sorted(sentences)
    words = [len(t.split()) for t in sentences.values()]
    assert min(words) >= 10 and max(words) <= 16 and 12.5 < sum(words) / len(words) < 15


def test_mix_of_neutral_one_and_two_word_sentences(corpus):
    sentences, splits = corpus
    known = [n for n in sentences if n not in splits["test-unseen"]]
    counts = collections.Counter(len(emotional_words(sentences[n], TRAIN_LEXICON)) for n in known)
    assert abs(counts[0] / len(known) - 0.25) < 0.01 and abs(counts[1] / len(known) - 0.60) < 0.01
    assert abs(counts[2] / len(known) - 0.15) < 0.01
    pairs = [emotional_words(sentences[n]) for n in known]
    assert any(len(p) == 2 and LEXICON[p[0]].cls != LEXICON[p[1]].cls for p in pairs)


def test_every_class_is_well_covered_in_training(corpus):
    sentences, splits = corpus
    per_class = collections.Counter()
    for n in splits["train"]:
        for cls in {TRAIN_LEXICON[w].cls for w in emotional_words(sentences[n], TRAIN_LEXICON)}:
            per_class[cls] += 1
    assert min(per_class[c] for c in CLASSES) >= 200, per_class
    used = {w for n in splits["train"] for w in emotional_words(sentences[n])}
    adjectives = {w for w, e in TRAIN_LEXICON.items() if e.role != "other"}
    assert len(used & adjectives) > 0.9 * len(adjectives)


def test_held_out_words_only_in_test_unseen_and_their_twins(corpus):
    sentences, splits = corpus
    for name in ("train", "val", "test"):
        assert not any(emotional_words(sentences[n], HELD_OUT_LEXICON) for n in splits[name]), name
    unseen = splits["test-unseen"]
    assert len(unseen) >= 200
    held = [emotional_words(sentences[n]) for n in unseen]
    assert all(len(h) == 1 and h[0] in HELD_OUT_LEXICON for h in held)
    adjectives = {w for w, e in HELD_OUT_LEXICON.items() if e.role != "other"}
    assert {h[0] for h in held} == adjectives  # every held-out adjective is tested
    for n in unseen:
        twin = neutral_twin(n)
        assert twin != sentences[n] and emotional_words(twin) == []
        changed = [(a, b) for a, b in zip(sentences[n].split(), twin.split()) if a != b]
        assert len(changed) == 1 and len(twin.split()) == len(sentences[n].split())
        assert HELD_OUT_LEXICON[changed[0][0].strip(",.?!")].role != "other"
    with pytest.raises(KeyError, match="not a test-unseen"):
        neutral_twin(splits["train"][0])


def test_deterministic_and_seeded():
    a = generated_sentences(seed=7)  # a seed no other test uses: not cached
    assert a == generated_sentences(seed=7) and a != generated_sentences(seed=8)
    small = generated_sentences(200, seed=3)
    assert len(small) == 200 and len(generated_splits(200)["test-unseen"]) == 20
    check_generated(200, seed=3)


def test_sequence_names_of_generated_sentences(corpus):
    sentences, _ = corpus
    assert sequence_name("F2", 49) == "F2_e49" and sequence_name("M1", max(sentences)) == "M1_e2448"


ARTICLE_EXCEPTIONS = {"hour", "honest", "honour", "heir"}  # "an" before a silent h


def test_sentences_read_naturally(corpus):
    """Every sentence and neutral twin is one well-formed sentence: a capital first, single spaces, one
    final . ? or !, no word twice in a row, "a"/"an" agreeing with the next word, "was"/"were" with the
    pronoun before it."""
    sentences, splits = corpus
    texts = {**{f"e{n:02d}": t for n, t in {**SENTENCES, **sentences}.items()},
             **{f"twin of e{n:02d}": neutral_twin(n) for n in splits["test-unseen"]}}
    for name, text in texts.items():
        assert re.fullmatch(r"[A-Z][^ ?!]*( [^ ?!]+)*[.?!]", text), f"{name} is not one sentence: {text!r}"
        assert not re.search(r"\b(\w+) \1\b", text, re.IGNORECASE), f"{name} repeats a word: {text!r}"
        for article, word in re.findall(r"\b(a|an) (\w+)", text, re.IGNORECASE):
            vowel = word[0].lower() in "aeiou" or word.lower() in ARTICLE_EXCEPTIONS
            assert vowel == (article.lower() == "an"), f"{name}: {article} {word}: {text!r}"
        disagree = re.search(r"\b(he|she|it) were\b|\b(we|they|you) was\b", text, re.IGNORECASE)
        assert not disagree, f"{name}: {disagree.group()}: {text!r}"
