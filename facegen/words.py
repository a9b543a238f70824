"""Words and their times: `Word`, transcript normalisation (what a recogniser hears: lower case,
numbers spelled out with num2words, stage directions left out) and the word rate speech can have. The
alignment files (word timings on disk) are facegen.alignment_files'.

Words keep the user's spelling (`Word.text`); `normalize_transcript` gives the spoken tokens of each.
Scripts carry what is not said: stage directions, notes and sound descriptions in brackets ("(laughs)",
"[tone]", "<beep>", "*sighs*"); `split_directions` sets them apart, and they never reach the aligner.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass
from fractions import Fraction

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
_SPELLED_OUT = 16  # numbers of this many digits or more (10**15 on) are said digit by digit
_DIGITS = ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine")


def _said(n: int, to: str = "cardinal") -> list[str]:
    """num2words' English as spoken tokens: 342 → three hundred forty two (no "and", no hyphens)."""
    from num2words import num2words

    return [w for w in re.split(r"[\s,-]+", num2words(n, to=to)) if w and w != "and"]


def _digits(digits: str) -> list[str]:
    return [_DIGITS[int(d)] for d in digits]


def cardinal(digits: str) -> list[str]:
    """English words for a non-negative integer written in decimal digits: "342" → three hundred forty two;
    one of _SPELLED_OUT digits or more digit by digit (never converted to an int: Python refuses to convert
    more than 4,300 digits)."""
    digits = digits.lstrip("0") or "0"
    return _digits(digits) if len(digits) >= _SPELLED_OUT else _said(int(digits))


def ordinal(digits: str) -> list[str]:
    """English ordinal words for decimal digits: "3" → third, "21" → twenty first."""
    digits = digits.lstrip("0") or "0"
    if len(digits) >= _SPELLED_OUT:
        return _digits(digits[:-1]) + _said(int(digits[-1]), "ordinal")
    return _said(int(digits), "ordinal")


def _integer(digits: str) -> list[str]:
    if len(digits) > 1 and digits.startswith("0"):
        return _digits(digits)  # 007 → zero zero seven
    if len(digits) == 4 and (1100 <= int(digits) <= 1999 or 2010 <= int(digits) <= 2099):
        return _said(int(digits), "year")  # 1990 → nineteen ninety, 1905 → nineteen oh five
    return cardinal(digits)


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


def _numeral(ch: str) -> str | None:
    """A number sign that is not a decimal digit ("①", "²", "Ⅻ", "½") as words to say, or None."""
    if unicodedata.category(ch) not in ("No", "Nl"):
        return None
    value = unicodedata.numeric(ch, None)
    if value is None:
        return None
    if value == int(value):
        return " ".join(cardinal(str(int(value))))
    fraction = Fraction(value).limit_denominator(1000)
    denominator = {2: ["half", "halves"], 4: ["quarter", "quarters"]}.get(fraction.denominator)
    one = denominator[0] if denominator else ordinal(str(fraction.denominator))[-1]
    many = denominator[1] if denominator else _plural([one])[0]
    return " ".join(cardinal(str(fraction.numerator)) + [one if fraction.numerator == 1 else many])


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
    if any(_numeral(ch) for ch in token):  # "①" → one, "1½" → one one half, "m²" → m two
        token = "".join(f" {said} " if (said := _numeral(ch)) else ch for ch in token)
        return [word for part in token.split() for word in _spoken(strip_edges(part))]
    if m := _RE_CURRENCY.fullmatch(token):
        symbol, amount, mult = m.groups()
        one, many, sub_one, sub_many = _CURRENCIES[symbol]
        if mult:
            return _number(amount) + [_MULTIPLIERS[mult.lower()], many]
        whole, _, frac = amount.replace(",", "").partition(".")
        words = cardinal(whole or "0") + [one if whole == "1" else many]
        if frac and len(frac) == 2 and int(frac):
            words += ["and"] + cardinal(frac) + [sub_one if frac == "01" else sub_many]
        elif frac:
            words = _number(amount) + [many]
        return words
    if m := _RE_PERCENT.fullmatch(token):
        return _number(m.group(1)) + ["percent"]
    if m := _RE_ORDINAL.fullmatch(token):
        return ordinal(m.group(1))
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
            words += _integer(part) if part[0].isdecimal() else [part.lower()]
    return words


# --------------------------------------------------------------------------------------------------
# stage directions

_CLOSING = {"(": ")", "[": "]", "{": "}", "<": ">"}
_OPENING = {close: opening for opening, close in _CLOSING.items()}
_RE_BRACKET = re.compile(r"[()\[\]{}]|<(?!\s)|(?<!\s)>")  # <beep>, not a < b > c
_RE_STARRED = re.compile(r"(?<![\w*])\*[^\s*](?:[^*]*[^\s*])?\*(?![\w*])")  # *sighs*, not 3 * 4


def _direction_spans(text: str) -> list[tuple[int, int]]:
    """(start, end) of each outermost stage direction in `text`, in order: matching brackets ("[tone (long)]"
    is one), "<" and ">" only with no space just inside, or asterisks around words ("*sighs*"). An unclosed
    bracket opens none. One pass over the brackets: hostile text ("((((...") costs linear time."""
    stacks: dict[str, list[int]] = {opening: [] for opening in _CLOSING}
    pairs = [m.span() for m in _RE_STARRED.finditer(text)]
    for m in _RE_BRACKET.finditer(text):
        ch, at = m.group(), m.start()
        if ch in _CLOSING:
            stacks[ch].append(at)
        elif stacks[_OPENING[ch]]:
            pairs.append((stacks[_OPENING[ch]].pop(), at + 1))
    outermost: list[tuple[int, int]] = []
    for start, end in sorted(pairs, key=lambda pair: (pair[0], -pair[1])):
        if not outermost or start >= outermost[-1][1]:
            outermost.append((start, end))
    return outermost


def split_directions(text: str) -> tuple[str, list[str]]:
    """`text` without its stage directions, and the directions as written (whitespace collapsed).

    A stage direction, note or sound description is a span in brackets ("(laughs)", "[tone]", "<beep>",
    "{music}", "(note: does not say "2")") or between asterisks ("*sighs*"); a parenthesis that holds no
    letter ("(50%)", "(2)") is read aloud. Each direction leaves a space behind: "yes(laughs)no" is two words.
    """
    spoken: list[str] = []
    directions: list[str] = []
    done = 0
    for start, end in _direction_spans(text):
        span = text[start:end]
        if span[0] == "(" and not any(ch.isalpha() for ch in span):
            continue
        spoken += [text[done:start], " "]
        directions.append(" ".join(span.split()))
        done = end
    return "".join(spoken) + text[done:], directions


def no_words(text: str) -> FacegenError:
    """The error for a transcript with no word to say: empty, or only stage directions (its own message)."""
    directions = split_directions(text)[1]
    if not directions:
        return FacegenError("the transcript is empty: pass the words spoken in the audio", param="text")
    shown = " ".join(directions)
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    return FacegenError(f"the transcript holds only a stage direction, {shown}, and no spoken word: pass the "
                        "words spoken in the audio (what is in brackets is not said)", param="text")


# --------------------------------------------------------------------------------------------------
# acronyms

MAX_SPELLED = 6  # an all-caps token of at most this many letters may be said letter by letter ("IAX")


def spelled(word: str, token: str) -> list[str] | None:
    """The letters of `token` as the dictionary's letter words ("iax" → ["i.", "a.", "x."]) when `word`, as
    written, has it in capitals ("IAX", "SIP-based", "R&D"), so it may be said letter by letter; else None.
    The aligner offers them beside the word itself and picks what was said."""
    if not (token.isascii() and token.isalpha() and len(token) <= MAX_SPELLED and token.upper() in word):
        return None
    return [f"{letter}." for letter in token]


def normalize_transcript(text: str) -> list[tuple[str, list[str]]]:
    """For each whitespace-separated word of `text`: (the word, edge punctuation stripped; its spoken tokens).

    Spoken tokens are lower case without punctuation, numbers spelled out ("42" → ["forty", "two"],
    "3rd" → ["third"], "$5" → ["five", "dollars"], a 5,000-digit number digit by digit, "①" → ["one"]; an
    identifier such as "extension 1234" digit by digit: DIGIT_KEYS).
    Words made only of punctuation are left out, and so are stage directions (`split_directions`).
    """
    out = []
    for raw in split_directions(text)[0].split():
        word = strip_edges(raw)
        if not word:
            continue
        spoken = _spoken(word)
        if out and _said_as_digits(out[-1][0], word):
            spoken = _digits(word)
        if spoken:
            out.append((word, spoken))
    return out


# words after which a number of DIGITS_AFTER_KEY digits or more names something and is said digit by digit
# ("extension 1234" → one two three four, "password 4242", "PIN 0815"), not as a quantity or a year
DIGIT_KEYS = frozenset({"extension", "ext", "password", "passcode", "pin", "code", "id", "account", "phone",
                        "number", "no", "zip", "flight", "room", "mailbox", "box", "dial"})
DIGITS_AFTER_KEY = 4


def _said_as_digits(before: str, word: str) -> bool:
    return (word.isascii() and word.isdigit() and len(word) >= DIGITS_AFTER_KEY
            and before.lower().rstrip(".#:") in DIGIT_KEYS)


_FULL_WIDTH = {code: code - 0xFEE0 for code in range(0xFF01, 0xFF5F)}  # ！..～ → !..~


def spoken_words(text: str, language: str = "en") -> list[tuple[str, list[str]]]:
    """`normalize_transcript` for English; in another language (a code of facegen.languages) each word with
    what espeak-ng is given to say it as its one token, lower case: espeak-ng says its numbers and
    abbreviations in that language's rules (words made only of punctuation and stage directions left out).
    Text in a script written without spaces (Chinese, Japanese, Thai) is split into its words
    (facegen.segmentation); a Japanese word is said as its reading in kana. Full-width digits and letters
    (３, ＯＫ, common in those scripts) are said as the ones espeak-ng reads (it says nothing for a full-width
    digit in Chinese)."""
    from facegen.segmentation import segment, unspaced

    if language == "en":
        return normalize_transcript(text)
    out = []
    for raw in split_directions(text)[0].split():
        word = strip_edges(raw)
        for written, said in segment(word, language) if unspaced(word, language) else [(word, word)]:
            written = strip_edges(written)
            if any(c.isalnum() for c in written):
                out.append((written, [said.translate(_FULL_WIDTH).lower()]))
    return out


def check_word_rate(words: int, duration: float, what: str) -> None:
    """Refuse `words` words for `duration` seconds of audio when no speech is that fast (before any work)."""
    allowed = max(MIN_WORDS_ALLOWED, MAX_WORDS_PER_SECOND * duration)
    if words > allowed:
        rate = words / max(duration, 1e-3)
        raise FacegenError(f"{what} has {words} words for {duration:.1f} s of audio ({rate:.0f} words/s; "
                           f"speech has at most about {MAX_WORDS_PER_SECOND:g}): is it the transcript of "
                           "another recording?")
