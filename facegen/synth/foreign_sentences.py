"""Sentences in the voices corpus's other languages (facegen.synth.voices.CORPUS_LANGUAGES): strings of the
language's common words, drawn from wordfreq's word lists (`pip install facegen[corpus]`; wordfreq's data is
CC BY-SA 4.0, drawn from Wikipedia, subtitles, news, books and the web).

The lips learn phones, not grammar: what a language's speech sounds like and how its words are said is what
the corpus needs, and the language's commonest words give its phones in their everyday proportions. A
sentence is 5-11 words drawn from the top TOP words with probability ∝ frequency ** FLATTEN (function words
stay frequent, but content words are common enough to carry the rarer phones), the first capitalised, a
comma after a random word in long ones, a full stop or question mark at the end. Words are kept when every
character is a letter or mark of the language's scripts (facegen.languages.SCRIPTS): no digits, no
abbreviations, no foreign-script names, no lone consonant letters (the fragments of French l' or d').

No emotional word is ever drawn: none of the English lexicons' (facegen.synth.lexicon.LEXICON, what the rig's
upper face answers) and none of any language's emotional lexicon (facegen/lexicons.json, which the text
encoder reads glossed). The rig gives these sentences a neutral upper face, which is right for them, and every
emotional word of another language stays unseen in training (the held-out test of facegen.lexicons).
"""

from __future__ import annotations

import re
import unicodedata
from functools import cache

import numpy as np

from facegen.errors import FacegenError

TOP = 3000
FLATTEN = 0.4
WORDS = (5, 11)  # words per sentence, inclusive


VOWELS = set("aeiouyαεηιουω")
LONE_CONSONANTS = {"cs": set("vszk")}  # one-consonant words that are words (prepositions), not fragments


def _is_word(word: str, scripts: set[str], code: str) -> bool:
    from facegen.languages import script_of

    if len(word) == 1 and script_of(word) in ("LATIN", "GREEK"):  # French l', d'; Greek σ': fragments
        base = unicodedata.normalize("NFD", word)[0]
        if base not in VOWELS and base not in LONE_CONSONANTS.get(code, ()):
            return False
    for c in word:
        category = unicodedata.category(c)
        if category.startswith("M"):
            continue
        if not category.startswith("L") or script_of(c) not in scripts:
            return False
    return True


@cache
def _emotional() -> frozenset[str]:
    """Every emotional word facegen knows, lower case: the English lexicons' and facegen/lexicons.json's."""
    from facegen.lexicons import LANGUAGES, lexicon
    from facegen.synth.lexicon import LEXICON

    return frozenset({w.lower() for w in LEXICON} | {w.lower() for code in LANGUAGES for w in lexicon(code)})


@cache
def word_list(code: str) -> tuple[tuple[str, ...], np.ndarray]:
    """The language's TOP commonest words that are written in its scripts, and their draw probabilities."""
    try:
        import wordfreq
    except ImportError as exc:
        raise FacegenError("the voices corpus's other languages need wordfreq's word lists: "
                           "pip install 'facegen[corpus]' (or wordfreq)") from exc
    from facegen.languages import check_language

    if code not in wordfreq.available_languages():
        raise FacegenError(f"wordfreq has no word list for {code!r}: choose a language it lists")
    scripts = set(check_language(code).scripts)
    words = [w for w in wordfreq.top_n_list(code, TOP)
             if _is_word(w, scripts, code) and w not in _emotional()]
    freqs = np.array([wordfreq.word_frequency(w, code) for w in words]) ** FLATTEN
    return tuple(words), freqs / freqs.sum()


def foreign_sentences(code: str, n: int, seed: int = 0) -> list[str]:
    """`n` sentences of language `code` (a function of the arguments and wordfreq's data only)."""
    words, p = word_list(code)
    rng = np.random.default_rng([seed, *code.encode()])
    out = []
    for _ in range(n):
        count = int(rng.integers(WORDS[0], WORDS[1] + 1))
        picked = [words[i] for i in rng.choice(len(words), size=count, p=p)]
        if count >= 8:
            k = int(rng.integers(2, count - 2))
            picked[k] += ","
        first = picked[0]
        picked[0] = first[0].upper() + first[1:]
        text = " ".join(picked) + ("?" if rng.random() < 0.15 else ".")
        out.append(re.sub(r"σ\b", "ς", text) if code == "el" else text)  # wordfreq folds final sigma
    return out
