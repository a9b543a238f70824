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
from dataclasses import dataclass

import numpy as np

from facegen.align_pieces import RATE
from facegen.phonetics import is_filler
from facegen.sphinx import FRAME, LOCK, base_word, decode, get_decoder, pcm16k, pcm_bytes
from facegen.words import Word

SURE = 0.5  # a recognised word at least this likely drives the upper face (see the module docstring)


@dataclass
class Heard:
    """The recognised words in time and each one's posterior probability (0-1)."""

    words: list[Word]
    confidences: list[float]

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
    """The words of `recognize` and each one's confidence (see the module docstring)."""
    audio = pcm16k(audio, sample_rate)
    pcm = pcm_bytes(audio)
    with LOCK:
        decoder = get_decoder("recognize")
        segments = [(base_word(w), first, last) for w, first, last in decode(decoder, pcm)
                    if not is_filler(w)]
        links = _lattice_links(decoder) if segments else []
    duration = len(audio) / RATE
    words = [Word(w, round(first * FRAME, 3), round(min((last + 1) * FRAME, duration), 3))
             for w, first, last in segments]
    return Heard(words, [_posterior(w, (first + last + 1) / 2 * FRAME, links) for w, first, last in segments])


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
