"""Speech recognition without a transcript: pocketsphinx's default US English model hears the words (less
accurate than forced alignment of a transcript, facegen.align; their timing is usually close), each with how
sure the recogniser is of it.

A word's confidence is its posterior probability in the recogniser's word lattice: the summed posteriors of
the lattice's links for the same word that span the word's midpoint (pocketsphinx writes each link's
posterior into the HTK lattice it saves; its Python API gives no other way to them). Measured on Asterisk's
recorded prompts (8 kHz telephone speech, where 47 % of the recognised words are right; odd-numbered half,
67 lines, 961 words): the words at 0.5 or above are right 71 % of the time, and three quarters of the wrong
words fall below it (benchmarks/bench_recognition.py).
"""

from __future__ import annotations

import os
import tempfile
import warnings
from dataclasses import dataclass

import numpy as np

from facegen.align_pieces import HOP, RATE, loud_frames, pieces
from facegen.errors import FacegenError
from facegen.phonetics import is_filler
from facegen.sphinx import FRAME, LOCK, base_word, clip_cmn, decode, get_decoder, pcm16k, pcm_bytes
from facegen.words import Word

SURE = 0.5  # a recognised word at least this likely drives the upper face (see the module docstring)
LONG_SECONDS = 60.0  # longer audio is recognised piece by piece (see the module docstring)
MAX_PIECE_SECONDS = 15.0  # a piece without a pause is split into parts at most this long
STEP_SECONDS = 0.5  # audio given to pocketsphinx per call


@dataclass
class Heard:
    """The recognised words in time and each one's posterior probability (0-1)."""

    words: list[Word]
    confidences: list[float]
    phones: list | None = None  # (phone, start, end) in the words, when heard piece by piece (long audio)

    @property
    def sure(self) -> list[Word]:
        """The words the recogniser is sure of (SURE): the ones that may drive the upper face."""
        return [w for w, c in zip(self.words, self.confidences, strict=True) if c >= SURE]


def recognize(audio: np.ndarray, sample_rate: int) -> list[Word]:
    """Words recognised in `audio` without a transcript (pocketsphinx's default US English model).

    Less accurate than `align` with a transcript: words may be wrong; their timing is usually close.
    """
    return hear(audio, sample_rate).words


def hear(audio: np.ndarray, sample_rate: int) -> Heard:
    """The words of `recognize` and each one's confidence (see the module docstring); audio over LONG_SECONDS
    piece by piece, with their phones."""
    audio = pcm16k(audio, sample_rate)
    pcm = pcm_bytes(audio)
    if len(audio) > LONG_SECONDS * RATE:
        return _hear_pieces(audio, pcm)
    with LOCK:
        decoder = get_decoder("recognize")
        segments = [(base_word(w), first, last) for w, first, last in decode(decoder, pcm)
                    if not is_filler(w)]
        links = _lattice_links(decoder) if segments else []
    duration = len(audio) / RATE
    words = [Word(w, round(first * FRAME, 3), round(min((last + 1) * FRAME, duration), 3))
             for w, first, last in segments]
    return Heard(words, [_posterior(w, (first + last + 1) / 2 * FRAME, links) for w, first, last in segments])


def _hear_pieces(audio: np.ndarray, pcm: bytes) -> Heard:
    """`hear` of long audio: piece by piece, each with its words' phones (see the module docstring)."""
    from facegen.align import state_pass, word_phones

    duration, longest = len(audio) / RATE, int(MAX_PIECE_SECONDS * 100)
    spans = [(a + k * (b - a) // parts, a + (k + 1) * (b - a) // parts)
             for a, b in pieces(loud_frames(audio, len(audio) // HOP))
             for parts in [-(-(b - a) // longest)] for k in range(parts)]
    heard = Heard([], [], [])
    with LOCK:
        cmn = clip_cmn(pcm)
        decoder = get_decoder("recognize-long")
        search = decoder.current_search()
        for first, end in spans:
            part = pcm[first * HOP * 2:end * HOP * 2]
            decoder.activate_search(search)  # the state pass of the piece before left its own
            segments = [(base_word(w), a, b) for w, a, b in _decode_in_steps(decoder, part, cmn)
                        if not is_filler(w)]
            if not segments:
                continue
            links = _lattice_links(decoder)
            heard.words += [Word(w, round((first + a) * FRAME, 3),
                                 round(min((first + b + 1) * FRAME, duration), 3)) for w, a, b in segments]
            heard.confidences += [_posterior(w, (a + b + 1) / 2 * FRAME, links) for w, a, b in segments]
            try:
                alignment = state_pass(decoder, part, cmn)
            except (FacegenError, RuntimeError):  # no phones for this piece: the audio drives its lips
                continue
            heard.phones += [phone for word in word_phones(alignment, 0, len(segments), first, duration)
                             for phone in word]
    return heard


def _decode_in_steps(decoder, pcm: bytes, cmn: str) -> list[tuple[str, int, int]]:
    """sphinx.decode, the audio given STEP_SECONDS at a time (each call returns to Python)."""
    decoder.set_cmn(cmn)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # as in sphinx.decode: the only reset there is
        decoder.start_stream()
    decoder.start_utt()
    step = int(STEP_SECONDS * RATE) * 2
    for s in range(0, len(pcm), step):
        decoder.process_raw(pcm[s:s + step], no_search=False, full_utt=False)
    decoder.end_utt()
    return [(s.word, s.start_frame, s.end_frame) for s in (decoder.seg() or [])]


def _lattice_links(decoder) -> list[tuple[str, float, float, float]]:
    """The word lattice of the last utterance as (word, start s, end s, posterior) per link."""
    lattice = decoder.get_lattice()
    if lattice is None:
        return []
    handle, path = tempfile.mkstemp(prefix="facegen-lattice-", suffix=".slf")
    os.close(handle)
    try:
        lattice.write_htk(path)
        with open(path, encoding="utf-8", errors="replace") as file:
            lines = file.read().splitlines()
    finally:
        os.unlink(path)
    nodes: dict[str, tuple[float, str]] = {}
    links = []
    for line in lines:
        fields = dict(part.split("=", 1) for part in line.split("\t") if "=" in part)
        if "I" in fields:
            nodes[fields["I"]] = (float(fields["t"]), fields["W"])
        elif "J" in fields:
            (start, word), end = nodes[fields["S"]], nodes[fields["E"]][0]
            links.append((base_word(word), start, max(end, start + FRAME), float(fields["p"])))
    return links


def _posterior(word: str, middle: float, links: list[tuple[str, float, float, float]]) -> float:
    """The summed posterior of the links for `word` that span `middle` (s), at most 1."""
    return round(min(sum(p for w, start, end, p in links if w == word and start <= middle < end), 1.0), 3)
