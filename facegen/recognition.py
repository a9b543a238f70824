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
from facegen.phonetics import is_filler
from facegen.sphinx import FRAME, LOCK, base_word, clip_cmn, decode, get_decoder, pcm16k, pcm_bytes
from facegen.words import Word

SURE = 0.5  # a recognised word at least this likely drives the upper face (see the module docstring)
LONG_SECONDS = 60.0  # longer audio is recognised piece by piece (see the module docstring)
MAX_PIECE_SECONDS = 15.0  # a piece without a pause is split into parts at most this long
STEP_SECONDS = 0.5  # audio given to pocketsphinx per call
LM_SEARCH = "_default"  # pocketsphinx's name of a decoder's language-model search


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
    """`hear` of long audio: piece by piece, each with its words' phones (see the module docstring); the
    second half in a forked process where there is a second core (`_helper`)."""
    duration, longest = len(audio) / RATE, int(MAX_PIECE_SECONDS * 100)
    spans = [(a + k * (b - a) // parts, a + (k + 1) * (b - a) // parts)
             for a, b in pieces(loud_frames(audio, len(audio) // HOP))
             for parts in [-(-(b - a) // longest)] for k in range(parts)]
    with LOCK:
        cmn = clip_cmn(pcm)
        get_decoder("recognize-long")  # made before the fork: the helper has it too
    half = int(np.searchsorted([b for _, b in spans], spans[-1][1] / 2)) + 1
    helper = _helper(pcm, spans[half:], cmn, duration)
    try:
        heard = _hear_spans(pcm, spans[:half] if helper else spans, cmn, duration)
        rest = helper.result() if helper else None
        if helper and rest is None:  # the helper gave no answer: its half here
            rest = _hear_spans(pcm, spans[half:], cmn, duration)
    finally:
        if helper:
            helper.close()
    if rest is not None:
        heard.words, heard.confidences, heard.phones = (heard.words + rest.words,
                                                        heard.confidences + rest.confidences,
                                                        heard.phones + rest.phones)
    return heard


def _hear_spans(pcm: bytes, spans: list[tuple[int, int]], cmn: str, duration: float) -> Heard:
    """The words, confidences and phones of the pieces `spans` (frames) of `pcm`, in order."""
    from facegen.align import word_phones

    heard = Heard([], [], [])
    with LOCK:
        decoder = get_decoder("recognize-long")
        for first, end in spans:
            part = pcm[first * HOP * 2:end * HOP * 2]
            decoder.activate_search(LM_SEARCH)  # a state pass left its own
            segments = [(base_word(w), a, b) for w, a, b in _decode_in_steps(decoder, part, cmn)
                        if not is_filler(w)]
            if not segments:
                continue
            links = _lattice_links(decoder)
            heard.words += [Word(w, round((first + a) * FRAME, 3),
                                 round(min((first + b + 1) * FRAME, duration), 3)) for w, a, b in segments]
            heard.confidences += [_posterior(w, (a + b + 1) / 2 * FRAME, links) for w, a, b in segments]
            try:  # the state pass in steps too: a whole-utterance pass would change the pieces after it
                decoder.set_alignment()
                _decode_in_steps(decoder, part, cmn)
                alignment = decoder.get_alignment()
            except RuntimeError:
                alignment = None
            if alignment is not None:  # else no phones for this piece: the audio drives its lips
                heard.phones += [phone for word in word_phones(alignment, 0, len(segments), first, duration)
                                 for phone in word]
    return heard


HELPER_SECONDS = 120.0  # audio (the helper's half) worth a forked process


class _Helper:
    """A forked process hearing some pieces: `result()` waits for its Heard (None if it gave none), `close()`
    stops it."""

    def __init__(self, process, receiver) -> None:
        self.process, self.receiver = process, receiver

    def result(self) -> Heard | None:
        try:
            return self.receiver.recv()  # a signal interrupts the wait: close() then stops the helper
        except (EOFError, OSError):
            return None

    def close(self) -> None:
        if self.process.is_alive():
            self.process.kill()
        self.process.join()
        self.receiver.close()


def _helper(pcm: bytes, spans: list[tuple[int, int]], cmn: str, duration: float) -> _Helper | None:
    """The pieces `spans` heard in a forked process, on a second core: recognition is the slow part of a long
    clip without a transcript (about 6x real time per core). None where there is no second core, no fork,
    other threads (a fork copies their locks), a daemonic process (a batch's worker may not have children)
    or little audio."""
    import multiprocessing
    import threading

    from facegen.processes import start_process
    from facegen.runtime import cores

    if (cores() < 2 or threading.active_count() > 1 or multiprocessing.current_process().daemon
            or not spans or sum(b - a for a, b in spans) < HELPER_SECONDS * 100):
        return None
    receiver, sender = multiprocessing.Pipe(duplex=False)
    process = start_process(_hear_child, (sender, pcm, spans, cmn, duration), start="fork",
                            name="facegen-recognize")
    sender.close()
    if process is None:
        receiver.close()
        return None
    return _Helper(process, receiver)


def _hear_child(sender, pcm: bytes, spans: list[tuple[int, int]], cmn: str, duration: float) -> None:
    """In the forked helper: hear `spans` and send the Heard (nothing on an error: the parent hears them)."""
    import signal

    for name in ("SIGINT", "SIGTERM", "SIGHUP"):  # the parent decides: it kills this process when it stops
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    try:
        sender.send(_hear_spans(pcm, spans, cmn, duration))
    except Exception:  # noqa: BLE001, S110 - no traceback here: the parent hears these pieces itself
        pass
    finally:
        sender.close()


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
