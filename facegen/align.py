"""Word timing: forced alignment with pocketsphinx, recognition, and readers/writers of alignment files.

Words keep the user's spelling (`Word.text`); what the recogniser hears comes from
`normalize_transcript` (lower case, numbers spelled out), and every result maps back to the
original words. Words missing from pocketsphinx's dictionary get a pronunciation from libespeak-ng.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import threading
import unicodedata
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.errors import FacegenError

RATE = 16000  # pocketsphinx's en-us model
FRAME = 0.01  # pocketsphinx frame step (s)
TOLERANCE = 0.05  # how far (s) read times may run past the audio's end


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


_ONES = ("zero one two three four five six seven eight nine ten eleven twelve thirteen fourteen fifteen "
         "sixteen seventeen eighteen nineteen").split()
_TENS = "_ _ twenty thirty forty fifty sixty seventy eighty ninety".split()
_SCALES = ((10**12, "trillion"), (10**9, "billion"), (10**6, "million"), (1000, "thousand"))
_ORDINALS = {"one": "first", "two": "second", "three": "third", "five": "fifth", "eight": "eighth",
             "nine": "ninth", "twelve": "twelfth"}
_CURRENCIES = {"$": ("dollar", "dollars", "cent", "cents"), "€": ("euro", "euros", "cent", "cents"),
               "£": ("pound", "pounds", "penny", "pence"), "¥": ("yen", "yen", "sen", "sen")}
_SYMBOLS = {"&": "and", "+": "plus", "@": "at", "%": "percent", "#": "number", "=": "equals"}
_MULTIPLIERS = {"k": "thousand", "m": "million", "bn": "billion", "b": "billion"}


def cardinal(n: int) -> list[str]:
    """English words for a non-negative integer: 342 → three hundred forty two."""
    if n < 20:
        return [_ONES[n]]
    if n < 100:
        return [_TENS[n // 10]] + ([_ONES[n % 10]] if n % 10 else [])
    if n < 1000:
        return [_ONES[n // 100], "hundred"] + (cardinal(n % 100) if n % 100 else [])
    if n >= 10**15:
        return [_ONES[int(d)] for d in str(n)]
    for value, name in _SCALES:
        if n >= value:
            return cardinal(n // value) + [name] + (cardinal(n % value) if n % value else [])
    raise AssertionError(n)


def ordinal(n: int) -> list[str]:
    """English ordinal words: 3 → third, 21 → twenty first."""
    words = cardinal(n)
    last = words[-1]
    if last in _ORDINALS:
        last = _ORDINALS[last]
    elif last.endswith("y"):
        last = last[:-1] + "ieth"
    else:
        last += "th"
    return words[:-1] + [last]


def _year(n: int) -> list[str]:
    """A year as people say it: 1990 → nineteen ninety, 1905 → nineteen oh five, 2024 → twenty twenty four."""
    high, low = divmod(n, 100)
    if low == 0:
        return cardinal(high) + ["hundred"]
    return cardinal(high) + (["oh", _ONES[low]] if low < 10 else cardinal(low))


def _integer(digits: str) -> list[str]:
    if len(digits) > 1 and digits.startswith("0"):
        return [_ONES[int(d)] for d in digits]  # 007 → zero zero seven
    n = int(digits)
    if len(digits) == 4 and (1100 <= n <= 1999 or 2010 <= n <= 2099):
        return _year(n)
    return cardinal(n)


def _number(text: str) -> list[str]:
    """Words for "1,234", "3.14", "42"."""
    whole, _, frac = text.replace(",", "").partition(".")
    words = _integer(whole) if whole else ["zero"]
    if frac:
        words += ["point"] + [_ONES[int(d)] for d in frac]
    return words


def _plural(words: list[str]) -> list[str]:
    last = words[-1]
    last = last[:-1] + "ies" if last.endswith("y") else last + ("es" if last.endswith("x") else "s")
    return words[:-1] + [last]


_NUM = r"\d{1,3}(?:,\d{3})+(?:\.\d+)?|\d+(?:\.\d+)?|\.\d+"
_RE_CURRENCY = re.compile(rf"([$€£¥])({_NUM})(k|m|bn|b)?", re.I)
_RE_PERCENT = re.compile(rf"({_NUM})%")
_RE_ORDINAL = re.compile(r"(\d+)(st|nd|rd|th)", re.I)
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


# --------------------------------------------------------------------------------------------------
# pronunciations: pocketsphinx's dictionary, else libespeak-ng phonemes mapped to its phone set

_ESPEAK_TO_CMU = {
    # vowels (espeak-ng English mnemonics)
    "@": "AH", "@2": "AH", "@5": "AH", "@L": "AH L", "3": "ER", "3:": "ER", "a": "AE", "a#": "AH",
    "A:": "AA", "A@": "AA R", "A#": "AE", "aa": "AE", "aI": "AY", "aI@": "AY ER", "aI3": "AY ER",
    "aU": "AW", "aU@": "AW ER", "E": "EH", "e": "EH", "e@": "EH R", "eI": "EY", "i": "IY", "i:": "IY",
    "I": "IH", "I#": "IH", "I2": "IH", "i@": "IY AH", "i@3": "IY R", "0": "AA", "O": "AO", "O:": "AO",
    "O2": "AO", "O@": "AO R", "o@": "AO R", "OI": "OY", "oU": "OW", "oU#": "OW", "o": "OW", "u": "UW",
    "u:": "UW", "U": "UH", "U@": "UH R", "V": "AH", "IR": "IH R", "VR": "AH R", "y": "UW", "Y": "UW",
    # consonants
    "b": "B", "d": "D", "D": "DH", "dZ": "JH", "f": "F", "g": "G", "h": "HH", "j": "Y", "k": "K",
    "l": "L", "m": "M", "n": "N", "N": "NG", "p": "P", "r": "R", "r-": "R", "s": "S", "S": "SH", "t": "T",
    "T": "TH", "tS": "CH", "v": "V", "w": "W", "z": "Z", "Z": "ZH", "t#": "T", "d#": "D", "t2": "T",
    "d2": "D", "n-": "N", "m-": "M", "l-": "L", "x": "K", "C": "HH", "W": "W", "hw": "W", "l/": "L",
    "l/2": "L", "z/2": "Z", "R": "R", "*": "R", "r/": "R", "?": "T",
}
_STRESS = str.maketrans("", "", "'`,%=")
_LONGEST = max(len(k) for k in _ESPEAK_TO_CMU)


def espeak_to_cmu(phonemes: list[str]) -> list[str]:
    """Map espeak phoneme mnemonics to pocketsphinx (CMU) phones; unknown symbols are skipped."""
    out: list[str] = []
    for ph in phonemes:
        ph = ph.translate(_STRESS)
        i = 0
        while i < len(ph):  # longest match, so "aI@" or unusual compounds still map
            for size in range(min(_LONGEST, len(ph) - i), 0, -1):
                cmu = _ESPEAK_TO_CMU.get(ph[i:i + size])
                if cmu:
                    for p in cmu.split():
                        if not out or out[-1] != p or p not in _CONSONANTS:  # "bb" → B
                            out.append(p)
                    i += size
                    break
            else:
                i += 1
    return out


_CONSONANTS = set("B CH D DH F G HH JH K L M N NG P R S SH T TH V W Y Z ZH".split())


def pronounce(token: str) -> list[str]:
    """CMU phones for a spoken token, from libespeak-ng's grapheme-to-phoneme rules."""
    from facegen.synth.speech import phonemize  # shares the one loaded libespeak-ng

    return espeak_to_cmu(phonemize(token))


# --------------------------------------------------------------------------------------------------
# pocketsphinx

_LOCK = threading.RLock()
_DECODERS: dict[str, object] = {}
# wide beams: alignment search is constrained by the transcript, so it stays cheap, and noisy speech
# needs them
_ALIGN_CONFIG = dict(lm=None, beam=1e-80, wbeam=1e-60, pbeam=1e-80, loglevel="FATAL")
_RECOGNIZE_CONFIG = dict(beam=1e-60, wbeam=1e-40, pbeam=1e-60, loglevel="FATAL")


def _decoder(kind: str):
    if kind not in _DECODERS:
        import pocketsphinx

        config = _ALIGN_CONFIG if kind == "align" else _RECOGNIZE_CONFIG
        try:
            _DECODERS[kind] = pocketsphinx.Decoder(samprate=RATE, **config)
        except (RuntimeError, ValueError) as exc:
            raise FacegenError(f"cannot start pocketsphinx ({exc}): reinstall it with "
                               "`pip install --force-reinstall pocketsphinx`") from exc
    return _DECODERS[kind]


def _dictionary_word(decoder, token: str) -> str:
    """The decoder's dictionary entry for `token`, adding one from espeak's G2P if missing."""
    key = unicodedata.normalize("NFKD", token).encode("ascii", "ignore").decode()
    key = re.sub(r"[^a-z0-9']", "", key.lower())
    if key and decoder.lookup_word(key) is not None:
        return key
    key = key or f"oov{abs(hash(token)) % 10**8}"
    phones = pronounce(token) or ["AH"]
    decoder.add_word(key, " ".join(phones), True)
    return key


def _pcm16k(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """Mono float audio at any rate → 16 kHz float32, with the checks a user's audio needs."""
    audio = np.asarray(audio, dtype=np.float32)
    if audio.ndim == 2:
        audio = audio.mean(axis=1 if audio.shape[1] <= 8 else 0)
    if audio.ndim != 1 or sample_rate <= 0:
        raise FacegenError("audio must be mono samples with a positive sample rate: pass a mono signal")
    if len(audio) < 0.25 * sample_rate:
        raise FacegenError(f"the audio is too short ({len(audio) / max(sample_rate, 1):.2f} s): "
                           "use at least a quarter second of speech")
    if not np.all(np.isfinite(audio)):
        raise FacegenError("the audio contains NaN or infinite samples: check the audio file")
    if sample_rate != RATE:
        import soxr

        audio = soxr.resample(audio, sample_rate, RATE).astype(np.float32)
    peak = float(np.max(np.abs(audio)))
    if peak < 1e-3:
        raise FacegenError("the audio is silent: check the audio file (or its channel / volume)")
    return audio


def _decode(decoder, audio: np.ndarray) -> list[tuple[str, int, int, int]]:
    """Run one utterance; return segments (word, first frame, last frame, acoustic score)."""
    peak = float(np.max(np.abs(audio)))
    pcm = (audio * (0.9 * 32767 / max(peak, 1e-9))).astype("<i2").tobytes()  # normalised level
    decoder.start_utt()
    decoder.process_raw(pcm, no_search=False, full_utt=True)
    decoder.end_utt()
    return [(s.word, s.start_frame, s.end_frame, s.ascore) for s in (decoder.seg() or [])]


def _base(word: str) -> str:
    return re.sub(r"\(\d+\)$", "", word)


def _is_filler(word: str) -> bool:
    return word in ("<s>", "</s>", "<sil>") or word.startswith("[") or word.startswith("+")
