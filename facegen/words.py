"""Words and their times: `Word`, transcript normalisation (what a recogniser hears: lower case,
numbers spelled out with num2words) and the word rate speech can have. The alignment files (word timings on
disk) are facegen.alignment_files'.

Words keep the user's spelling (`Word.text`); `normalize_transcript` gives the spoken tokens of each.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass

from facegen.errors import FacegenError

MAX_WORDS_PER_SECOND = 10.0  # fast speech is 4-6 words/s; auctioneers reach ~7
MIN_WORDS_ALLOWED = 12  # a short clip may still hold a few quick words


@dataclass
class Word:
    """A word of the transcript as the user wrote it (edge punctuation stripped) and its time in seconds."""

    text: str
    start: float
    end: float


# --------------------------------------------------------------------------------------------------
# transcript normalisation

_KEEP_AT_EDGES = set("%$€£¥#&@+")


def strip_edges(token: str) -> str:
    """`token` without punctuation at its edges (symbols such as $ and % are kept; case kept)."""
    start, end = 0, len(token)
    while start < end and _is_punct(token[start]):
        start += 1
    while end > start and _is_punct(token[end - 1]):
        end -= 1
    return token[start:end]


def _is_punct(ch: str) -> bool:
    return ch not in _KEEP_AT_EDGES and unicodedata.category(ch)[0] in "PSZC"


_CURRENCIES = {"$": ("dollar", "dollars", "cent", "cents"), "€": ("euro", "euros", "cent", "cents"),
               "£": ("pound", "pounds", "penny", "pence"), "¥": ("yen", "yen", "sen", "sen")}
_SYMBOLS = {"&": "and", "+": "plus", "@": "at", "%": "percent", "#": "number", "=": "equals"}
_MULTIPLIERS = {"k": "thousand", "m": "million", "bn": "billion", "b": "billion"}
_SPELLED_OUT = 10**15  # from here on, numbers are said digit by digit


def _said(n: int, to: str = "cardinal") -> list[str]:
    """num2words' English as spoken tokens: 342 → three hundred forty two (no "and", no hyphens)."""
    from num2words import num2words

    return [w for w in re.split(r"[\s,-]+", num2words(n, to=to)) if w and w != "and"]


def _digits(digits: str) -> list[str]:
    return [word for d in digits for word in _said(int(d))]


def cardinal(n: int) -> list[str]:
    """English words for a non-negative integer: 342 → three hundred forty two."""
    return _digits(str(n)) if n >= _SPELLED_OUT else _said(n)


def ordinal(n: int) -> list[str]:
    """English ordinal words: 3 → third, 21 → twenty first."""
    if n >= _SPELLED_OUT:
        return _digits(str(n)[:-1]) + _said(n % 10, "ordinal")
    return _said(n, "ordinal")


def _integer(digits: str) -> list[str]:
    if len(digits) > 1 and digits.startswith("0"):
        return _digits(digits)  # 007 → zero zero seven
    n = int(digits)
    if len(digits) == 4 and (1100 <= n <= 1999 or 2010 <= n <= 2099):
        return _said(n, "year")  # 1990 → nineteen ninety, 1905 → nineteen oh five, 1900 → nineteen hundred
    return cardinal(n)


def _number(text: str) -> list[str]:
    """Words for "1,234", "3.14", "42"."""
    whole, _, frac = text.replace(",", "").partition(".")
    words = _integer(whole) if whole else ["zero"]
    if frac:
        words += ["point"] + _digits(frac)
    return words


def _plural(words: list[str]) -> list[str]:
    last = words[-1]
    last = last[:-1] + "ies" if last.endswith("y") else last + ("es" if last.endswith("x") else "s")
    return words[:-1] + [last]


_NUM = r"\d{1,3}(?:,\d{3})+(?:\.\d+)?|\d+(?:\.\d+)?|\.\d+"
_RE_CURRENCY = re.compile(rf"([$€£¥])({_NUM})(k|m|bn|b)?", re.IGNORECASE)
_RE_PERCENT = re.compile(rf"({_NUM})%")
_RE_ORDINAL = re.compile(r"(\d+)(st|nd|rd|th)", re.IGNORECASE)
_RE_DECADE = re.compile(r"(\d+0)'?s")
_RE_NUMBER = re.compile(_NUM)
_RE_PIECE = re.compile(r"\d+|[^\W\d_]+(?:'[^\W\d_]+)*", re.UNICODE)


def _spoken(token: str) -> list[str]:
    """The spoken words for one written word (already edge-stripped)."""
    token = token.replace("’", "'").replace("‘", "'")
    if m := _RE_CURRENCY.fullmatch(token):
        symbol, amount, mult = m.groups()
        one, many, sub_one, sub_many = _CURRENCIES[symbol]
        if mult:
            return _number(amount) + [_MULTIPLIERS[mult.lower()], many]
        whole, _, frac = amount.replace(",", "").partition(".")
        words = cardinal(int(whole or 0)) + [one if whole == "1" else many]
        if frac and len(frac) == 2 and int(frac):
            words += ["and"] + cardinal(int(frac)) + [sub_one if frac == "01" else sub_many]
        elif frac:
            words = _number(amount) + [many]
        return words
    if m := _RE_PERCENT.fullmatch(token):
        return _number(m.group(1)) + ["percent"]
    if m := _RE_ORDINAL.fullmatch(token):
        return ordinal(int(m.group(1)))
    if m := _RE_DECADE.fullmatch(token):
        return _plural(_integer(m.group(1)))
    if _RE_NUMBER.fullmatch(token):
        return _number(token)
    words: list[str] = []
    for piece in re.split(r"([&+@%#=])", token):
        if piece in _SYMBOLS:
            words.append(_SYMBOLS[piece])
            continue
        for m in _RE_PIECE.finditer(piece):
            part = m.group()
            words += _integer(part) if part.isdigit() else [part.lower()]
    return words


def normalize_transcript(text: str) -> list[tuple[str, list[str]]]:
    """For each whitespace-separated word of `text`: (the word, edge punctuation stripped; its spoken tokens).

    Spoken tokens are lower case without punctuation, numbers spelled out ("42" → ["forty", "two"],
    "3rd" → ["third"], "$5" → ["five", "dollars"]). Words made only of punctuation are left out.
    """
    out = []
    for raw in text.split():
        word = strip_edges(raw)
        if not word:
            continue
        spoken = _spoken(word)
        if spoken:
            out.append((word, spoken))
    return out


def check_word_rate(words: int, duration: float, what: str) -> None:
    """Refuse `words` words for `duration` seconds of audio when no speech is that fast (before any work)."""
    allowed = max(MIN_WORDS_ALLOWED, MAX_WORDS_PER_SECOND * duration)
    if words > allowed:
        rate = words / max(duration, 1e-3)
        raise FacegenError(f"{what} has {words} words for {duration:.1f} s of audio ({rate:.0f} words/s; "
                           f"speech has at most about {MAX_WORDS_PER_SECOND:g}): is it the transcript of "
                           "another recording?")
