"""Long audio cut into pieces at its pauses, so that forced alignment runs piece by piece.

Pocketsphinx's alignment passes cost time (and, for the state-level pass, memory) that grow faster than
the audio's length, and one hard spot fails a whole long search. `facegen.align` therefore aligns pieces
of about PIECE_SECONDS, cut in the middle of pauses found from the audio's energy (`loud_frames`): each
piece but the last takes as many of the next transcript words as its speech holds (a grammar that may
end after any word, `prefix_grammar`), the last one all the words left. Only some pieces, spread over
the clip (`scored`), are scored by the mismatch check. A piece is aligned together with the first
LOOKAHEAD frames after it, and keeps the words that start before its end: the words at a cut are aligned
knowing what follows them, as in one long search (none squeezed into the pause, none left out). Each piece but
the first also aligns again the last word of the piece before it (from LOOKBEHIND frames before that word) and
drops it: its first word's onset is then found after speech, as in one long search, not at the start of a
search (whose noise estimate starts afresh, putting that onset up to 90 ms earlier).

Pieces re-synchronise. A prefix search may give the speech of a piece's last words to its filler model and
place those words on the next piece's audio (found on a 2-hour loop of recorded prompts: the words of one
line put on the next line's, after which every piece started with words already said and fell further
behind, the repeated prompts letting each piece pass). So when a piece leaves RESYNC_LOUD loud frames before
its cut outside its words (`unheld`), the next one is searched from its cut with a grammar that may also
start up to RESYNC_WORDS words later (each such start weighted SKIP_PROB); the words it skips are aligned
again, forced, with the piece before, over its audio up to the first word the next piece kept.

The outer edges of the words come from the audio too (`speech_edges`): pocketsphinx often gives a clip's
first or last sound to its silence model — the /s/ of "six", the aspiration of "tick", above all in telephone
audio, whose missing band above 4 kHz is where the acoustic model expects them — and a lone word in silence
then starts up to 0.3 s late. The first word starts, and the last one ends, where the loud sound they begin
and end in does.

Frames are pocketsphinx's: 10 ms apart.
"""

from __future__ import annotations

import itertools

import numpy as np

RATE = 16000  # pocketsphinx's en-us model
HOP = RATE // 100  # samples per 10 ms frame
PIECE_SECONDS = 6.0  # a piece ends in the first pause after this much audio
MIN_PAUSE = 0.25  # s of quiet audio that may separate two pieces
SCORED_SECONDS = 10.0  # audio the mismatch check scores at least (all of it when shorter)
LOOKAHEAD = 150  # frames of the next piece aligned with a piece, so that its last words have what follows
LOOKBEHIND = 10  # a piece's search starts this many frames before the last word of the piece before, with it
MAX_EDGE = 40  # frames the first word's start and the last word's end may move out to the sound they are in
MAX_SEARCH = 6000  # frames of the longest search: a piece that fails is joined with the next up to this
RESYNC_LOUD = 30  # loud frames a piece leaves outside its words before its cut: the next may skip words
RESYNC_WORDS = 20  # words the next piece may then skip (said in the piece before)
SKIP_PROB = 1e-3  # a grammar's weight of starting after skipped words


def loud_frames(audio: np.ndarray, n_frames: int, rate: int = RATE) -> np.ndarray:
    """Frames (10 ms step, 25 ms window) clearly louder than the recording's noise floor (`audio` at
    `rate` Hz)."""
    energy = frame_energy_db(audio, n_frames, rate)
    low, high = np.percentile(energy, 10), np.percentile(energy, 95)
    return energy > low + 0.5 * (high - low)


def frame_energy_db(audio: np.ndarray, n_frames: int, rate: int = RATE) -> np.ndarray:
    """The level (dB) of `n_frames` frames of `audio` at `rate` Hz: 10 ms step, 25 ms window."""
    win, hop = int(0.025 * rate), rate // 100
    energy = np.empty(n_frames)
    for s in range(0, n_frames, 1 << 14):  # a block of frames at a time: 2 h of them are 2.3 GB as float64
        e = min(s + (1 << 14), n_frames)
        under = audio[s * hop:(e - 1) * hop + win]  # the samples under them, zeros past the end
        under = np.pad(under, (0, (e - 1 - s) * hop + win - len(under)))
        block = np.lib.stride_tricks.sliding_window_view(under, win)[::hop].astype(np.float64)
        energy[s:e] = 10 * np.log10(np.mean(block ** 2, axis=1) + 1e-12)
    return energy


def pieces(loud: np.ndarray) -> list[tuple[int, int]]:
    """(first frame, end frame) of consecutive pieces covering every frame: each cut in the middle of a
    run of at least MIN_PAUSE quiet frames, once the piece has PIECE_SECONDS; the last piece at least half
    that long. One piece when the audio is short or has no pause."""
    n, length, pause = len(loud), int(PIECE_SECONDS * 100), int(MIN_PAUSE * 100)
    edges = np.flatnonzero(np.diff(np.concatenate([[1], loud.astype(np.int8), [1]])))  # quiet run bounds
    cuts = [0]
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        middle = (start + end) // 2
        if end - start >= pause and middle - cuts[-1] >= length and n - middle >= length // 2:
            cuts.append(int(middle))
    cuts.append(n)
    return list(itertools.pairwise(cuts))


def scored(spans: list[tuple[int, int]]) -> set[int]:
    """Indices of the pieces the mismatch check scores: evenly spread, SCORED_SECONDS of audio at least."""
    lengths = [b - a for a, b in spans]
    for count in range(1, len(spans) + 1):
        chosen = set(np.linspace(0, len(spans) - 1, count).round().astype(int).tolist())
        if sum(lengths[i] for i in chosen) >= SCORED_SECONDS * 100:
            return chosen
    return set(range(len(spans)))


def word_window(left: int, piece: int, rest: int) -> int:
    """How many of the `left` transcript words a piece of `piece` frames is offered, out of `rest` frames
    still to align: its share of the words with a wide margin (a piece taking them all is tried again)."""
    return min(left, int(1.5 * left * piece / max(rest, 1)) + 8)


def prefix_grammar(decoder, name: str, keys: list[str], may_end: bool = True, skippable: int = 0):
    """A pocketsphinx grammar of `keys` in order that may end after any of them (`may_end`, else only after
    the last) and start at any of the first `skippable` + 1 (a later start weighted SKIP_PROB). Each word
    also leads to the final state (no empty transitions: their "(NULL)" segments would stop the state-level
    pass)."""
    n = len(keys)
    transitions = [(i, i + 1, 1.0, key) for i, key in enumerate(keys)]
    if may_end:
        transitions += [(i, n, 1.0, key) for i, key in enumerate(keys[:-1])]
    transitions += [(0, i + 1, SKIP_PROB, keys[i]) for i in range(1, min(skippable + 1, n))]
    return decoder.create_fsg(name, 0, n, transitions)


def skipped(said: list[str], keys: list[str], skippable: int, whole: bool) -> int | None:
    """How many of `keys` a search that said `said` skipped at its start (at most `skippable`), when `said`
    follows `keys` from there (to their end when `whole`); None when it does not."""
    for skip in range(min(skippable, len(keys) - 1) + 1):
        if said and said == keys[skip:skip + len(said)] and (not whole or skip + len(said) == len(keys)):
            return skip
    return None


def unheld(loud: np.ndarray, words: list[tuple[str, int, int]], end: int) -> int:
    """Loud frames from the first of `words` (dictionary word, first frame, last frame) up to `end` that none
    of them holds."""
    if not words:
        return 0
    free = loud[words[0][1]:end].copy()
    for _, first, last in words:
        free[max(first - words[0][1], 0):last + 1 - words[0][1]] = False
    return int(free.sum())


def speech_edges(loud: np.ndarray, first: int, last: int) -> tuple[int, int]:
    """The first word's first frame and the last word's last frame, each moved out to the edge of the run of
    loud frames it falls in, when that edge is at most MAX_EDGE frames away (a longer run of sound before the
    first word or after the last is speech the transcript may not hold: it stays outside)."""
    start, end = first, last
    if loud[first]:
        while start > 0 and loud[start - 1]:
            start -= 1
        start = start if first - start <= MAX_EDGE else first
    if loud[last]:
        while end + 1 < len(loud) and loud[end + 1]:
            end += 1
        end = end if end - last <= MAX_EDGE else last
    return start, end
