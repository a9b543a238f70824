"""Emotional words whose meaning moves the upper face of the synthetic speakers.

Each word has an expression class (see facegen.synth.rig.EXPRESSIONS: surprise raises the brows, anger
and sadness frown, fear and awe widen the eyes, joy raises the cheeks) and an intensity in (0, 1].

TRAIN_LEXICON may appear in training sentences. HELD_OUT_LEXICON must never appear in training
sentences: it tests whether a model generalises from what words mean to emotional words it never saw.
LEXICON (both) is what the ground-truth rig responds to.
"""

from __future__ import annotations

import re
from dataclasses import dataclass


@dataclass(frozen=True)
class Emotion:
    cls: str  # a key of facegen.synth.rig.EXPRESSIONS
    intensity: float


def _entries(cls: str, words: str) -> dict[str, Emotion]:
    """Parse "word:intensity word:intensity ..." into lexicon entries of one class."""
    out = {}
    for item in words.split():
        word, value = item.split(":")
        out[word] = Emotion(cls, float(value))
    return out


TRAIN_LEXICON: dict[str, Emotion] = {
    **_entries("surprise", """
        surprise:0.9 surprised:0.9 surprising:0.8 amazing:0.9 amazed:0.9 astonishing:1.0 astonished:1.0
        unexpected:0.7 suddenly:0.6 sudden:0.6 wow:1.0 incredible:0.9 unbelievable:0.9 shocking:1.0
        shocked:1.0 startled:0.8 stunning:0.8 stunned:0.9 whoa:1.0 remarkable:0.6 extraordinary:0.7
        amazement:0.9"""),
    **_entries("anger", """
        angry:0.9 anger:0.8 furious:1.0 fury:1.0 rage:1.0 hate:0.9 hated:0.9 annoyed:0.5 annoying:0.5
        irritated:0.6 outrageous:0.8 mad:0.7 hostile:0.7 bitter:0.6 resent:0.6 disgusting:0.8 disgust:0.8
        livid:1.0 enraged:1.0 infuriating:0.9 angrily:0.9"""),
    **_entries("sadness", """
        sad:0.8 sadly:0.7 sorrow:0.9 grief:1.0 grieving:1.0 miserable:0.9 lonely:0.7 tragic:0.9
        tragedy:0.9 heartbroken:1.0 mourn:0.9 mourning:0.9 gloomy:0.6 unhappy:0.7 depressed:0.8
        despair:1.0 crying:0.8 tears:0.7 regret:0.6 sorry:0.5 sadness:0.8"""),
    **_entries("fear", """
        afraid:0.8 scared:0.9 frightened:0.9 fear:0.8 terrified:1.0 terror:1.0 horror:1.0 horrible:0.8
        dreadful:0.8 dread:0.8 panic:0.9 nervous:0.5 anxious:0.6 worried:0.5 alarming:0.7 danger:0.7
        dangerous:0.7 threat:0.6 creepy:0.6 scary:0.8 frightening:0.9"""),
    **_entries("awe", """
        awesome:0.8 magnificent:0.9 majestic:0.8 breathtaking:1.0 wonderful:0.7 marvelous:0.8
        spectacular:0.9 glorious:0.8 splendid:0.7 sublime:0.8 enormous:0.6 vast:0.5 immense:0.6
        miracle:0.9 wonder:0.7"""),
    **_entries("joy", """
        happy:0.8 happiness:0.8 joy:0.9 joyful:0.9 delighted:0.9 delight:0.8 glad:0.6 cheerful:0.7
        love:0.7 lovely:0.6 laugh:0.8 laughing:0.9 smile:0.7 smiling:0.8 fun:0.6 pleased:0.6
        excited:0.8 thrilled:0.9 celebrate:0.7 grateful:0.6 laughed:0.8 smiled:0.7 loved:0.7 delightful:0.8"""),
}

HELD_OUT_LEXICON: dict[str, Emotion] = {
    **_entries("surprise", "flabbergasted:1.0 dumbfounded:0.9 staggering:0.8 bewildered:0.7"),
    **_entries("anger", "seething:1.0 wrathful:0.9 irate:0.9 indignant:0.7"),
    **_entries("sadness", "forlorn:0.8 woeful:0.8 desolate:0.9 melancholy:0.7"),
    **_entries("fear", "petrified:1.0 aghast:0.9 ghastly:0.8 trembling:0.7"),
    **_entries("awe", "resplendent:0.9 stupendous:0.9 monumental:0.7 transcendent:0.8"),
    **_entries("joy", "jubilant:1.0 elated:0.9 ecstatic:1.0 overjoyed:1.0"),
}

LEXICON: dict[str, Emotion] = {**TRAIN_LEXICON, **HELD_OUT_LEXICON}

_EDGES = re.compile(r"^[^\w']+|[^\w']+$")


def normalise_word(text: str) -> str:
    """Lower-case, edge punctuation and possessive 's removed ("Wow!" -> "wow", "fear's" -> "fear")."""
    word = _EDGES.sub("", text.strip().lower()).strip("'")
    return word.removesuffix("'s")


def lookup(text: str, lexicon: dict[str, Emotion] | None = None) -> Emotion | None:
    """The emotion of one word (as written in a transcript), or None when it carries none."""
    return (LEXICON if lexicon is None else lexicon).get(normalise_word(text))


def emotional_words(text: str, lexicon: dict[str, Emotion] | None = None) -> list[str]:
    """The words of `text` found in `lexicon` (all of LEXICON by default), normalised, in order."""
    table = LEXICON if lexicon is None else lexicon
    return [w for w in (normalise_word(t) for t in text.split()) if w in table]
