"""Word timing: forced alignment with pocketsphinx, recognition, and readers/writers of alignment files.

Words keep the user's spelling (`Word.text`); what the recogniser hears comes from
`normalize_transcript` (lower case, numbers spelled out), and every result maps back to the
original words. Words missing from pocketsphinx's dictionary get a pronunciation from libespeak-ng.
"""

from __future__ import annotations

import csv
import io
import itertools
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


_ONES = ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten", "eleven",
         "twelve", "thirteen", "fourteen", "fifteen", "sixteen", "seventeen", "eighteen", "nineteen")
_TENS = ("", "", "twenty", "thirty", "forty", "fifty", "sixty", "seventy", "eighty", "ninety")
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
    """A year as said: 1990 → nineteen ninety, 1905 → nineteen oh five, 2024 → twenty twenty four"""
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


_CONSONANTS = ("B", "CH", "D", "DH", "F", "G", "HH", "JH", "K", "L", "M", "N", "NG", "P", "R", "S", "SH", "T",
               "TH", "V", "W", "Y", "Z", "ZH")


def pronounce(token: str) -> list[str]:
    """CMU phones for a spoken token, from libespeak-ng's grapheme-to-phoneme rules."""
    from facegen.synth.speech import phonemize  # shares the one loaded libespeak-ng

    return espeak_to_cmu(phonemize(token))


# --------------------------------------------------------------------------------------------------
# pocketsphinx

_LOCK = threading.RLock()
_DECODERS: dict[str, object] = {}
_PRONOUNCED: dict[int, set[str]] = {}  # id(decoder) → words whose espeak pronunciation is in its dictionary
# Alignment tries these in turn until every word is placed. bestpath=False: the lattice pass after the
# FSG search drops valid alignments. Wide beams rescue noisy speech (the search is constrained by the
# transcript, so they stay affordable); fillers (noise/breath models) sometimes derail it.
_WIDE = {"beam": 1e-120, "wbeam": 1e-100, "pbeam": 1e-120, "maxhmmpf": -1}
_CONFIGS = {
    "align": {"lm": None, "bestpath": False},
    "align-wide": {"lm": None, "bestpath": False, **_WIDE},
    "align-nofiller": {"lm": None, "bestpath": False, "fsgusefiller": False, **_WIDE},
    "recognize": {},
}
_VOWELS = ("AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW", "OY", "UH", "UW")
_PHONES = _VOWELS + _CONSONANTS
_PHONE_WORD = {p: f"phone_{p.lower()}" for p in _PHONES}  # one-phone words, to align a free phone loop
# A transcript that does not match the speech (see _check_match): more than this share of the loud
# frames left outside its words, or a median word fitting the sounds worse than the best free phone
# sequence by more than this (per-frame gap to the best HMM state, pocketsphinx's log units).
MAX_UNEXPLAINED = 0.3
MAX_WORD_GAP = 22.0


def _decoder(kind: str):
    if kind not in _DECODERS:
        import pocketsphinx

        try:
            decoder = pocketsphinx.Decoder(samprate=RATE, loglevel="FATAL", **_CONFIGS[kind])
            if kind.startswith("align"):
                for phone, word in _PHONE_WORD.items():
                    decoder.add_word(word, phone, False)
                decoder.add_allphone_file("_phones", None)  # also refreshes the dictionary
        except (RuntimeError, ValueError) as exc:
            raise FacegenError(f"cannot start pocketsphinx ({exc}): reinstall it with "
                               "`pip install --force-reinstall pocketsphinx`") from exc
        _DECODERS[kind] = decoder
    return _DECODERS[kind]


def _dictionary_word(decoder, token: str) -> str:
    """The decoder's dictionary entry for `token`.

    A word missing from the dictionary gets espeak's pronunciation; a known word gets it as an
    alternative when it differs, so a quirk of either (CMUdict's "hmm" = HH M) does not derail it.
    New words go in without rebuilding the searches: set_align_text builds a fresh one.
    """
    key = unicodedata.normalize("NFKD", token).encode("ascii", "ignore").decode()
    key = re.sub(r"[^a-z0-9']", "", key.lower()).strip("'") or "oov_" + "_".join(f"{ord(c):x}" for c in token)
    done = _PRONOUNCED.setdefault(id(decoder), set())
    if key in done:
        return key
    known, n = [], 1
    while (pron := decoder.lookup_word(key if n == 1 else f"{key}({n})")) is not None:
        known.append(pron)
        n += 1
    phones = " ".join(pronounce(token) or ["AH"])
    if phones not in known:
        decoder.add_word(key if n == 1 else f"{key}({n})", phones, False)
    done.add(key)
    return key


def _pcm16k(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """Mono float audio at any rate → 16 kHz float32, after the checks a user's audio needs."""
    audio = np.asarray(audio, dtype=np.float32)
    if audio.ndim == 2:  # [samples, channels] or [channels, samples]
        audio = audio.mean(axis=1 if audio.shape[1] < audio.shape[0] else 0)
    if audio.ndim != 1 or sample_rate <= 0:
        raise FacegenError("audio must be a mono signal with a positive sample rate: pass one channel")
    if len(audio) < 0.25 * sample_rate:
        raise FacegenError(f"the audio is too short ({len(audio) / sample_rate:.2f} s): "
                           "use a recording with at least a quarter second of speech")
    if not np.all(np.isfinite(audio)):
        raise FacegenError("the audio contains NaN or infinite samples: check the audio file")
    if float(np.max(np.abs(audio))) < 1e-3:
        raise FacegenError("the audio is silent: check the audio file, its channel and its volume")
    if sample_rate != RATE:
        import soxr

        audio = soxr.resample(audio, sample_rate, RATE).astype(np.float32)
    return audio


def _pcm_bytes(audio: np.ndarray) -> bytes:
    """16-bit PCM at a standard level, over a faint noise floor: digital silence derails pocketsphinx."""
    level = float(np.percentile(np.abs(audio), 99.5)) or float(np.max(np.abs(audio)))
    x = audio * (0.5 / level)
    x = x + np.random.default_rng(0).normal(0.0, 1e-3, len(x)).astype(np.float32)
    return (np.clip(x, -1.0, 1.0) * 32767).astype("<i2").tobytes()


def _decode(decoder, pcm: bytes) -> list[tuple[str, int, int]]:
    """Run one utterance; return its segments (word, first frame, last frame inclusive)."""
    decoder.start_utt()
    decoder.process_raw(pcm, no_search=False, full_utt=True)
    decoder.end_utt()
    return [(s.word, s.start_frame, s.end_frame) for s in (decoder.seg() or [])]


def _base(word: str) -> str:
    return re.sub(r"\(\d+\)$", "", word)


def _is_filler(word: str) -> bool:
    return word.startswith(("<", "[", "+"))  # <s> </s> <sil> [NOISE] +SPN+ ...


def _state_gaps(decoder, pcm: bytes, n_frames: int) -> np.ndarray:
    """Per frame: how far the current alignment's HMM state scores below the best state of that frame.

    Runs pocketsphinx's second, state-level alignment pass over the current word alignment.
    """
    decoder.set_alignment()
    _decode(decoder, pcm)
    gaps = np.zeros(n_frames)
    for phone in decoder.get_alignment().phones():
        if phone.duration > 0:
            gaps[phone.start:phone.start + phone.duration] = -phone.score / phone.duration
    return gaps


def _free_gaps(decoder, pcm: bytes, n_frames: int) -> np.ndarray | None:
    """State gaps of the best unconstrained phone sequence: the fit a matching transcript nearly reaches."""
    decoder.activate_search("_phones")
    phones = [_PHONE_WORD[w] for w, _, _ in _decode(decoder, pcm) if w in _PHONE_WORD]
    if not phones:
        return None
    decoder.set_align_text(" ".join(phones))
    if not _decode(decoder, pcm):
        return None
    return _state_gaps(decoder, pcm, n_frames)


def _match_scores(decoder, pcm: bytes, n_frames: int,
                  words: list[tuple[str, int, int]]) -> tuple[np.ndarray, np.ndarray | None]:
    """State gaps of the word alignment and of the free phone loop, for _check_match.

    Both passes cost time and memory that grow faster than the audio's length (3 minutes in one pass:
    90 s and 1.3 GB; 10 minutes: more than 6 GB), so audio longer than CHECK_SECONDS is scored in
    segments of at most that length, cut in the longest pause between aligned words; each segment is
    aligned again with its own words and scored alone. At most CHECK_SEGMENTS segments, spread evenly
    over the clip, are scored (the frames of the others are NaN: their words are left out of the
    median); the share of speech outside the words is still measured on the whole clip. Falls back to
    one pass when a segment does not realign.
    """
    segments = _segments(words, n_frames)
    if len(segments) == 1:
        return _state_gaps(decoder, pcm, n_frames), _free_gaps(decoder, pcm, n_frames)
    gaps, free = np.full(n_frames, np.nan), np.full(n_frames, np.nan)
    chosen = np.unique(np.linspace(0, len(segments) - 1, min(CHECK_SEGMENTS, len(segments))).round().astype(int))
    for first, last, keys in (segments[i] for i in chosen):  # frames first..last-1
        part = pcm[first * _FRAME_BYTES:last * _FRAME_BYTES]
        decoder.set_align_text(" ".join(keys))
        if [_base(w) for w, _, _ in _decode(decoder, part) if not _is_filler(w)] != keys:
            decoder.set_align_text(" ".join(_base(w) for w, _, _ in words))
            _decode(decoder, pcm)
            return _state_gaps(decoder, pcm, n_frames), _free_gaps(decoder, pcm, n_frames)
        n = min(decoder.n_frames(), last - first)
        gaps[first:first + n] = _state_gaps(decoder, part, decoder.n_frames())[:n]
        seg_free = _free_gaps(decoder, part, decoder.n_frames())
        free[first:first + n] = gaps[first:first + n] if seg_free is None else seg_free[:n]
    return gaps, free


CHECK_SECONDS = 30.0  # longest stretch of audio scored in one pass by _match_scores
CHECK_SEGMENTS = 8  # most segments scored (4 minutes of audio at most)
_FRAME_BYTES = int(RATE * FRAME) * 2  # 16-bit PCM bytes per pocketsphinx frame


def _segments(words: list[tuple[str, int, int]], n_frames: int) -> list[tuple[int, int, list[str]]]:
    """(first frame, end frame, dictionary words) of segments of at most CHECK_SECONDS, cut in the middle
    of the longest pause between consecutive words in each segment's second half (one segment when the
    audio is short or no pause can be found)."""
    limit = int(CHECK_SECONDS / FRAME)
    if n_frames <= limit:
        return [(0, n_frames, [_base(w) for w, _, _ in words])]
    cuts, start, i = [0], 0, 0
    while n_frames - start > limit:
        best = None
        for j in range(i, len(words) - 1):
            end, following = words[j][2] + 1, words[j + 1][1]
            if following - start > limit:
                break
            if end - start >= limit // 2 and (best is None or following - end > best[0]):
                best = (following - end, (end + following) // 2, j + 1)
        if best is None:
            break
        start, i = best[1], best[2]
        cuts.append(start)
    cuts.append(n_frames)
    segments = []
    for a, b in itertools.pairwise(cuts):
        keys = [_base(w) for w, first, _ in words if a <= first < b]
        segments.append((a, b, keys))
    if any(not keys for _, _, keys in segments):
        return [(0, n_frames, [_base(w) for w, _, _ in words])]
    return segments


def _loud_frames(audio: np.ndarray, n_frames: int) -> np.ndarray:
    """Frames (10 ms step, 25 ms window) clearly louder than the recording's noise floor."""
    hop, win = RATE // 100, int(0.025 * RATE)
    padded = np.pad(audio, (0, max(0, n_frames * hop + win - len(audio))))
    frames = np.lib.stride_tricks.sliding_window_view(padded, win)[::hop][:n_frames]
    energy = 10 * np.log10(np.mean(frames.astype(np.float64) ** 2, axis=1) + 1e-12)
    low, high = np.percentile(energy, 10), np.percentile(energy, 95)
    return energy > low + 0.5 * (high - low)


def _mismatch(detail: str) -> FacegenError:
    return FacegenError(f"the transcript does not match the speech ({detail}): check the transcript, "
                        "or pass a ready alignment with --alignment FILE")


def _check_match(audio: np.ndarray, words: list[tuple[str, int, int]], gaps: np.ndarray,
                 free: np.ndarray | None) -> None:
    """Raise if the alignment shows that the transcript is not what was said.

    Two signs, measured on synthetic speech (12 sentences and a paragraph, 14 voices, clean, 10 and
    5 dB SNR) against matching and mismatched transcripts:
    - speech the transcript does not explain is left to silence/noise segments: a transcript with
      half of the words leaves 34-60 % of the loud frames outside words, a matching one under 7 %;
    - words forced onto sounds they are not fit them badly: the median word's state gap exceeds
      the free phone loop's by 16-64 (27+ when clean, 30+ at 10 dB) for a wrong sentence, by -5 to 17
      for the right one (13 at most down to 10 dB SNR). A typo or a swapped word passes, as it should.
    End to end on those 48 clips: every matching transcript passes; 46/48 wrong sentences and 47/48
    half transcripts are refused (the misses are at 10 and 5 dB SNR).
    """
    n = len(gaps)
    loud = _loud_frames(audio, n)
    in_words = np.zeros(n, bool)
    for _, first, last in words:
        in_words[first:last + 1] = True
    unexplained = float(np.sum(loud & ~in_words)) / max(int(np.sum(loud)), 1)
    if unexplained > MAX_UNEXPLAINED:
        raise _mismatch(f"{unexplained:.0%} of the speech lies outside its words")
    if free is not None:  # words in unscored segments of long audio are NaN and left out
        excess = float(np.nanmedian([gaps[f:l + 1].mean() - free[f:l + 1].mean() for _, f, l in words]))
        if excess > MAX_WORD_GAP:
            raise _mismatch(f"its words fit the sounds poorly, score gap {excess:.0f} > {MAX_WORD_GAP:.0f}")


def align(audio: np.ndarray, sample_rate: int, transcript: str) -> list[Word]:
    """Word start/end times (s) of `transcript` in `audio` (mono, any rate), by forced alignment.

    Returns one Word per written word of the transcript (words made only of punctuation are left
    out), in order, with the user's spelling. Raises FacegenError for an empty transcript, silent or
    too short audio, or a transcript that does not match the speech.
    """
    entries = normalize_transcript(transcript)
    if not entries:
        raise FacegenError('the transcript is empty: pass the words spoken in the audio (e.g. --text "...")')
    audio = _pcm16k(audio, sample_rate)
    pcm = _pcm_bytes(audio)
    spoken = [(i, token) for i, (_, tokens) in enumerate(entries) for token in tokens]
    with _LOCK:
        for kind in ("align", "align-wide", "align-nofiller"):
            decoder = _decoder(kind)
            keys = [_dictionary_word(decoder, token) for _, token in spoken]
            decoder.set_align_text(" ".join(keys))
            words = [s for s in _decode(decoder, pcm) if not _is_filler(s[0])]
            if [_base(w) for w, _, _ in words] == keys:
                break
        else:
            raise _mismatch("no alignment of its words to the audio exists")
        n_frames = decoder.n_frames()
        gaps, free = _match_scores(decoder, pcm, n_frames, words)
    _check_match(audio, words, gaps, free)
    duration = len(audio) / RATE
    times: dict[int, list[float]] = {}
    for (index, _), (_, first, last) in zip(spoken, words, strict=True):
        start, end = first * FRAME, min((last + 1) * FRAME, duration)
        times.setdefault(index, [start, end])[1] = end
    return [Word(entries[i][0], round(t[0], 3), round(t[1], 3)) for i, t in sorted(times.items())]


def recognize(audio: np.ndarray, sample_rate: int) -> list[Word]:
    """Words recognised in `audio` without a transcript (pocketsphinx's default US English model).

    Less accurate than `align` with a transcript: words may be wrong; their timing is usually close.
    """
    audio = _pcm16k(audio, sample_rate)
    pcm = _pcm_bytes(audio)
    with _LOCK:
        segments = _decode(_decoder("recognize"), pcm)
    duration = len(audio) / RATE
    return [Word(_base(w), round(first * FRAME, 3), round(min((last + 1) * FRAME, duration), 3))
            for w, first, last in segments if not _is_filler(w)]


# --------------------------------------------------------------------------------------------------
# alignment files: Gentle JSON, Praat/MFA TextGrid, WhisperX JSON, plain JSON, CSV

_PAUSE_LABELS = {"", "sil", "sp", "<eps>", "<sil>", "{sl}", "#"}


def read_alignment(path: str | os.PathLike, duration: float | None = None) -> list[Word]:
    """Read word timings from a Gentle / WhisperX / plain JSON, Praat or MFA TextGrid, or CSV file.

    The format is detected from the content. Pauses and words not found in the audio are left out.
    With `duration` (s), times past the audio's end (beyond a small tolerance) are an error, as are
    negative, reversed or overlapping times; the error names the file and the problem.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise FacegenError(f"cannot read alignment {path} ({exc.strerror}): check the path") from exc
    text = _decode_text(raw).lstrip()
    try:
        if text.startswith('File type = "ooTextFile"') or path.suffix.lower() == ".textgrid":
            words = _read_textgrid(text)
        elif text.startswith(("{", "[")):
            words = _read_json(json.loads(text))
        else:
            words = _read_csv(text)
    except (ValueError, KeyError, TypeError, IndexError) as exc:  # json.JSONDecodeError is a ValueError
        raise FacegenError(f"alignment {path} is malformed ({exc}): write it as Gentle/WhisperX/plain JSON, "
                           "a TextGrid or a CSV with word,start,end columns") from exc
    _validate(words, path, duration)
    return words


def _decode_text(raw: bytes) -> str:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):  # Praat writes UTF-16 when the text needs it
        return raw.decode("utf-16")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _word(text: object, start: object, end: object) -> Word | None:
    """A Word from file values; None for a pause or punctuation."""
    label = strip_edges(str(text).strip())
    if label.lower() in _PAUSE_LABELS:
        return None
    return Word(label, _seconds(start), _seconds(end))


def _seconds(value: object) -> float:
    if isinstance(value, bool) or value is None or value == "":
        raise ValueError(f"missing or invalid time {value!r}")
    number = float(value)  # ValueError for text
    if not math.isfinite(number):
        raise ValueError(f"time {value!r} is not a finite number")
    return number


def _read_json(data: object) -> list[Word]:
    if isinstance(data, dict) and ("segments" in data or "word_segments" in data):
        return _read_whisperx(data)
    items = data["words"] if isinstance(data, dict) else data
    if not isinstance(items, list):
        raise TypeError('expected a list of words or {"words": [...]}')
    gentle = any(isinstance(it, dict) and ("case" in it or "alignedWord" in it) for it in items)
    words = []
    for item in items:
        if not isinstance(item, dict):
            raise TypeError(f"word entry {item!r} is not an object")
        if gentle:  # Gentle: only "success" words have times
            if item.get("case", "success") != "success" or "start" not in item:
                continue
            word = _word(item.get("word", item.get("alignedWord", "")), item["start"], item["end"])
        else:
            label = item["word"] if "word" in item else item["text"]
            word = _word(label, item["start"], item["end"])
        if word:
            words.append(word)
    return words


def _read_whisperx(data: dict) -> list[Word]:
    """WhisperX (or Whisper with word timestamps): segments[].words[], else word_segments[].

    Words WhisperX could not time (often numbers) are placed in the gap between their neighbours.
    """
    segments = data.get("segments") or []
    if not isinstance(segments, list):
        raise TypeError("'segments' is not a list")
    items = [w for seg in segments for w in seg.get("words", [])] or data.get("word_segments") or []
    labels = [str(it["word"] if "word" in it else it["text"]) for it in items]
    starts = [it.get("start") for it in items]
    ends = [it.get("end") for it in items]
    i = 0
    while i < len(items):  # fill runs of untimed words between timed neighbours
        if starts[i] is not None and ends[i] is not None:
            i += 1
            continue
        j = i
        while j < len(items) and (starts[j] is None or ends[j] is None):
            j += 1
        left = _seconds(ends[i - 1]) if i > 0 else None
        right = _seconds(starts[j]) if j < len(items) else None
        if left is not None and right is not None and right >= left:
            step = (right - left) / (j - i)
            for k in range(i, j):
                starts[k], ends[k] = left + step * (k - i), left + step * (k - i + 1)
        i = j
    words = []
    for label, start, end in zip(labels, starts, ends, strict=True):
        if start is None or end is None:
            continue  # untimed at the edges: nothing to place it by
        word = _word(label, start, end)
        if word:
            words.append(word)
    return words


# a quoted string, an [index] (skipped), a flag, a number, or a label (skipped)
_TEXTGRID_TOKEN = re.compile(r'"((?:[^"]|"")*)"|\[\d*\]|(<exists>|<absent>)'
                             r'|(-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)|[A-Za-z_][A-Za-z_0-9 ]*\??|\S')


def _read_textgrid(text: str) -> list[Word]:
    """Praat TextGrid, long or short text format: the `words` tier, else the first interval tier."""
    values: list[str | float] = []
    for m in _TEXTGRID_TOKEN.finditer(text):
        if m.group(1) is not None:
            values.append(m.group(1).replace('""', '"'))
        elif m.group(3) is not None:
            values.append(float(m.group(3)))
    # both formats reduce to: "ooTextFile" "TextGrid" xmin xmax size, then per tier:
    # class name xmin xmax count and count intervals (xmin xmax text) or points (time mark)
    if values[:2] != ["ooTextFile", "TextGrid"]:
        raise ValueError("not a text TextGrid (save it from Praat as a text file)")
    pos, tiers = 5, []
    for _ in range(int(values[4])):
        kind, name, count = values[pos], values[pos + 1], int(values[pos + 4])
        pos += 5
        width = 3  # IntervalTier: xmin xmax text; TextTier: time mark
        if kind == "TextTier":
            width = 2
        elif kind != "IntervalTier":
            raise ValueError(f"unknown tier class {kind!r}")
        tiers.append((kind, str(name), values[pos:pos + width * count]))
        pos += width * count
    intervals = [t for t in tiers if t[0] == "IntervalTier"]
    if not intervals:
        raise ValueError("no interval tier")
    named = [t for t in intervals if re.search(r"\bwords?$", t[1].strip().lower())]  # MFA: "spk - words"
    _, _, flat = (named or intervals)[0]
    words = []
    for k in range(0, len(flat), 3):
        start, end, label = flat[k:k + 3]
        if not isinstance(label, str):
            raise TypeError(f"interval {k // 3 + 1} has no text")
        word = _word(label, start, end)
        if word:
            words.append(word)
    return words


def _read_csv(text: str) -> list[Word]:
    """CSV/TSV with a header naming word (or text/label), start and end; or 3 columns without one."""
    first = text.split("\n", 1)[0]
    delimiter = next((d for d in "\t,;" if d in first), ",")
    rows = [r for r in csv.reader(io.StringIO(text), delimiter=delimiter) if any(c.strip() for c in r)]
    if not rows:
        raise ValueError("the file is empty")
    header = [c.strip().lower() for c in rows[0]]
    names = {"word": ("word", "text", "label", "token"), "start": ("start", "begin", "onset", "start_time"),
             "end": ("end", "stop", "offset", "end_time")}
    columns = {key: next((header.index(a) for a in alias if a in header), None)
               for key, alias in names.items()}
    if all(v is not None for v in columns.values()):
        order, rows = (columns["word"], columns["start"], columns["end"]), rows[1:]
    else:
        if any(len(r) != 3 for r in rows):
            raise ValueError("rows without a word,start,end header must have exactly 3 columns")

        def numeric(cell: str) -> bool:
            try:
                float(cell)
                return True
            except ValueError:
                return False

        row = rows[0]
        text_cols = [i for i, c in enumerate(row) if not numeric(c)]
        if len(text_cols) != 1:
            raise ValueError(f"cannot tell the word column from the times in row {row}")
        word_col = text_cols[0]
        start_col, end_col = [i for i in range(3) if i != word_col]
        order = (word_col, start_col, end_col)
    words = []
    for n, row in enumerate(rows, 1):
        if len(row) <= max(order):
            raise ValueError(f"row {n} has too few columns")
        word = _word(row[order[0]], row[order[1]].strip(), row[order[2]].strip())
        if word:
            words.append(word)
    return words


def _validate(words: list[Word], path: Path, duration: float | None) -> None:
    def fail(problem: str) -> FacegenError:
        return FacegenError(f"alignment {path}: {problem}: fix the file or align again")

    if not words:
        raise fail("it contains no timed words")
    previous = None
    for w in words:
        if w.start < 0 or w.end < 0:
            raise fail(f"word {w.text!r} has a negative time ({w.start:g}-{w.end:g} s)")
        if w.end < w.start:
            raise fail(f"word {w.text!r} ends before it starts ({w.start:g}-{w.end:g} s)")
        if previous and (w.start < previous.start or w.start < previous.end - 0.01):
            raise fail(f"times are not in order: {w.text!r} at {w.start:g} s starts before "
                       f"{previous.text!r} ({previous.start:g}-{previous.end:g} s) ends")
        previous = w
    if duration is not None and words[-1].end > duration + TOLERANCE:
        raise fail(f"word {words[-1].text!r} ends at {words[-1].end:g} s, after the audio's end at "
                   f"{duration:g} s (is it the alignment of another recording?)")


def write_alignment(words: list[Word], path: str | os.PathLike, duration: float | None = None) -> Path:
    """Write words as our plain JSON ({"words": [{"word", "start", "end"}]}), a TextGrid or a CSV.

    The format follows the suffix (.json, .TextGrid, .csv). A TextGrid gets a `words` interval tier
    with empty intervals for pauses, spanning 0 to `duration` (default: the last word's end).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".json":
        payload = {"words": [{"word": w.text, "start": round(w.start, 6), "end": round(w.end, 6)}
                             for w in words]}
        content = json.dumps(payload, indent=1, ensure_ascii=False) + "\n"
    elif suffix == ".textgrid":
        content = _textgrid(words, duration)
    elif suffix == ".csv":
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(["word", "start", "end"])
        writer.writerows([w.text, f"{w.start:.6f}", f"{w.end:.6f}"] for w in words)
        content = buffer.getvalue()
    else:
        raise FacegenError(f"cannot write alignment {path}: use a .json, .TextGrid or .csv file name")
    with atomic_path(path) as tmp:
        tmp.write_text(content, encoding="utf-8")
    return path


def _textgrid(words: list[Word], duration: float | None) -> str:
    end = max([duration or 0.0] + [w.end for w in words])
    intervals: list[tuple[float, float, str]] = []
    t = 0.0
    for w in words:
        if w.start > t + 1e-9:
            intervals.append((t, w.start, ""))
        intervals.append((max(w.start, t), w.end, w.text))
        t = w.end
    if end > t + 1e-9 or not intervals:
        intervals.append((t, end, ""))
    lines = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "xmin = 0", f"xmax = {end:.6f}",
             "tiers? <exists>", "size = 1", "item []:", "    item [1]:", '        class = "IntervalTier"',
             '        name = "words"', "        xmin = 0", f"        xmax = {end:.6f}",
             f"        intervals: size = {len(intervals)}"]
    for k, (a, b, label) in enumerate(intervals, 1):
        quoted = label.replace('"', '""')
        lines += [f"        intervals [{k}]:", f"            xmin = {a:.6f}", f"            xmax = {b:.6f}",
                  f'            text = "{quoted}"']
    return "\n".join(lines) + "\n"
