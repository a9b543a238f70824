"""Words of scripts written without spaces between them (issue 25): a Chinese, Japanese or Thai sentence is
one run of letters, and split at whitespace alone it would be one "word" (one chunk to align, one text
feature, one word in the metadata and the mismatch check). `segment` splits such a run into its words:

- Chinese (Han characters, in cmn, yue, hak): rjieba (jieba's dictionary and HMM in Rust; a dependency);
  espeak-ng reads the characters, so each word is said as written.
- Japanese (ja): janome (a morphological analyser with the IPA dictionary; the extra `facegen[scripts]`):
  its morphemes joined into phrases, a content word with its particles and endings (_phrases).
  espeak-ng reads kana but not kanji (it says "Chinese letter" in English for each), so each word is said as
  janome's pronunciation of it, in katakana: 東京 → トーキョー, the particle は → ワ.
- Thai (th): pythainlp's newmm with its dictionary (the extra `facegen[scripts]`).

Everything runs offline from the packages' own dictionaries. Runs in other scripts (Latin words, digits)
inside such a transcript are words of their own.
"""

from __future__ import annotations

import os
import unicodedata
from functools import cache

from facegen.errors import FacegenError

# language code (facegen.languages) → the segmenter of its script
SEGMENTERS = {"cmn": "chinese", "yue": "chinese", "hak": "chinese", "ja": "japanese", "th": "thai"}
# the scripts (first word of a letter's Unicode name) each segmenter splits
_SCRIPTS = {"chinese": ("CJK",), "japanese": ("CJK", "HIRAGANA", "KATAKANA"), "thai": ("THAI",)}
_PACKAGES = {"chinese": "rjieba", "japanese": "janome", "thai": "pythainlp"}
_NAMES = {"chinese": "Chinese", "japanese": "Japanese", "thai": "Thai"}
_EXTRA = {"chinese": "facegen", "japanese": "facegen[scripts]", "thai": "facegen[scripts]"}


def unspaced(chunk: str, language: str) -> bool:
    """Whether `chunk` (a whitespace-separated piece of a transcript in `language`) holds letters of a script
    that `language` writes without spaces, so `segment` must split it into words."""
    kind = SEGMENTERS.get(language.lower())
    return kind is not None and any(_script(ch) in _SCRIPTS[kind] for ch in chunk)


def _script(ch: str) -> str:
    name = unicodedata.name(ch, "")
    return name.split()[0].split("-")[0] if name else ""  # KATAKANA-HIRAGANA PROLONGED SOUND MARK: KATAKANA


def segment(chunk: str, language: str) -> list[tuple[str, str]]:
    """The words of `chunk` (text with no whitespace, in `language`): (the word as written, what espeak-ng is
    given to say it: the word itself, or in Japanese its reading in katakana). Punctuation comes back as words
    of its own (the caller leaves out words without a letter or digit). A language that needs no segmenting
    gives the chunk whole. Raises FacegenError (one line: how to install it) when the package is missing."""
    kind = SEGMENTERS.get(language.lower())
    if kind is None:
        return [(chunk, chunk)]
    if kind == "chinese":
        return [(w, w) for w in _chinese()(chunk) if w.strip()]
    if kind == "japanese":
        return _phrases(chunk)
    return [(w, w) for w in _thai()(chunk) if w.strip()]


# morphemes said as one word with the one before: particles, auxiliary verbs, dependent adjectives and
# nouns, suffixes (東京 + の, 働い + て, い + ます). A dependent verb (いる) starts a word of its own: on
# synthetic Japanese, wrong transcripts were refused as often (56/60 against 57/60) and fewer lines became
# short ones, whose mismatch bound is wider (窓を 閉めて もらえますか, not 窓を 閉めてもらえますか).
_ATTACHED = ("助詞", "助動詞", "形容詞,非自立", "名詞,非自立", "名詞,接尾")


_ASCII_DIGITS = {code: code - 0xFEE0 for code in range(0xFF10, 0xFF1A)}  # ０..９ → 0..9


def _phrases(chunk: str) -> list[tuple[str, str]]:
    """A Japanese chunk's words: janome's morphemes, each attached morpheme (_ATTACHED) joined to the one
    before, so a word is a content word with its particles and endings (今日は, 働いて, います), said as
    their readings. Full-width digits are read as ASCII ones: janome splits ２０２４ into digits said one by
    one (ニ ゼロ ニ ヨン), espeak-ng says 2024 as a number; the words keep the spelling of `chunk`."""
    out: list[list[str]] = []
    at = 0
    for m in _japanese().tokenize(chunk.translate(_ASCII_DIGITS)):
        written, at = chunk[at:at + len(m.surface)], at + len(m.surface)
        if not written.strip():
            continue
        said = _reading(m)
        if out and m.part_of_speech.startswith(_ATTACHED) and any(c.isalnum() for c in out[-1][0]):
            out[-1][0] += written
            out[-1][1] += said
        else:
            out.append([written, said])
    return [(written, said) for written, said in out]


def _reading(morpheme) -> str:
    """A janome morpheme's pronunciation in katakana (は as a particle → ワ), or its spelling where it has
    none (a digit, a Latin word, a word not in the dictionary: espeak-ng reads those)."""
    said = morpheme.phonetic
    if said and said != "*" and all(_script(ch) in ("KATAKANA", "HIRAGANA") for ch in said):
        return said
    return morpheme.surface


def _missing(kind: str) -> FacegenError:
    return FacegenError(f"{_NAMES[kind]} transcripts need the package {_PACKAGES[kind]} to split their words "
                        f"(written without spaces): install it with `pip install '{_EXTRA[kind]}'`",
                        param="text")


@cache
def _chinese():
    try:
        import rjieba
    except ImportError:
        raise _missing("chinese") from None
    return rjieba.cut


@cache
def _japanese():
    try:
        from janome.tokenizer import Tokenizer
    except ImportError:
        raise _missing("japanese") from None
    return Tokenizer()


@cache
def _thai():
    # pythainlp makes a data folder on import (~/pythainlp-data): facegen's cache folder instead
    from facegen.runtime import cache_dir

    if not (os.environ.get("PYTHAINLP_DATA") or os.environ.get("PYTHAINLP_DATA_DIR")):
        os.environ["PYTHAINLP_DATA"] = str(cache_dir("pythainlp"))
    try:
        from pythainlp.tokenize import word_tokenize
    except ImportError:
        raise _missing("thai") from None
    return lambda text: word_tokenize(text, engine="newmm", keep_whitespace=False)
