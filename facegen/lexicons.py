"""Emotional words of other languages, read by the text encoder as English words it knows.

The built-in model's text features come from an English MiniLM (facegen.text), trained on English
sentences: it moves the upper face for "furious" but hears the French "furieux" as sub-word pieces with no
meaning. Until a multilingual encoder is trained in, each supported language has a lexicon
(facegen/lexicons.json, written for facegen) of its emotional words — adjectives in their inflected forms,
nouns, verbs — each glossed by an English word of the training lexicon (facegen.synth.lexicon's
TRAIN_LEXICON). `glossed` hands the encoder that English word in its place; every other word stays as
written, and the lips never see any of this (they follow the audio and the phones). Words match
case-insensitively, with their edge punctuation stripped.

Languages: LANGUAGES (French, German, Spanish, Italian, Portuguese, Russian).
"""

from __future__ import annotations

import json
import unicodedata
from collections.abc import Sequence
from functools import cache
from pathlib import Path

from facegen.words import strip_edges

_FILE = Path(__file__).with_name("lexicons.json")


@cache
def _lexicons() -> dict[str, dict[str, str]]:
    return {code: words for code, words in json.loads(_FILE.read_text(encoding="utf-8")).items()
            if not code.startswith("_")}


LANGUAGES = ("fr", "de", "es", "it", "pt", "ru")


def lexicon(language: str) -> dict[str, str]:
    """The emotional words of `language` (a code of facegen.languages) and their English glosses; empty for
    a language without a lexicon (English needs none)."""
    return _lexicons().get(language.split("-")[0], {})


def _key(word: str) -> str:
    return unicodedata.normalize("NFC", strip_edges(word)).lower()


def glossed(words: Sequence[str], language: str | None) -> list[str]:
    """`words` as the text encoder reads them: each emotional word of `language`'s lexicon replaced by its
    English gloss, the rest as written."""
    table = lexicon(language or "en")
    if not table:
        return list(words)
    return [table.get(_key(word), word) for word in words]
