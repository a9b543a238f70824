"""The mismatch check: does a transcript say what the speech says? Forced alignment (facegen.align) places a
transcript's words whatever was said; `judge` reads from that alignment two signs that it was not:

- speech the transcript does not explain is left to silence/noise segments: more than MAX_UNEXPLAINED of the
  loud frames outside the words (matching transcripts of recorded prompts: 0.25 at most);
- words forced onto sounds they are not fit them badly: the median word's state gap over a free phone loop
  above `word_gap_bound` (16 for clean speech, 25 under noise at 15 dB SNR and below);

and both halfway (PART_UNEXPLAINED, PART_WORD_GAP): no matching script measured does that. Measured:
benchmarks/bench_mismatch.py (Asterisk's recorded English prompts, 8 kHz, the odd half: 275/275 matching
scripts pass, 100/105 swapped rows refused) and benchmarks/calibrate_mismatch.py (synthetic voices clean and
at 10 and 5 dB SNR: matching refused 0/20 clean, 2/60 at 10 dB, 7/60 at 5 dB).

A `Match` holds both signs, their bounds, one `score` for sorting lines (1: sure, below 0.5: refused) and the
refusal's reason; the caller decides what a refusal does (`--on-mismatch error|warn`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from facegen.align_pieces import HOP
from facegen.errors import FacegenError

ON_MISMATCH = ("error", "warn")
# A transcript that does not match the speech: more than this share of the loud frames left outside its
# words, or a median word fitting the sounds worse than the best free phone sequence (per-frame gap to the
# best HMM state, pocketsphinx's log units) by more than word_gap_bound.
MAX_UNEXPLAINED = 0.3


def speech_snr_db(audio: np.ndarray) -> float:
    """How far the speech stands above the recording's noise (dB): the 90th against the 10th percentile of the
    10 ms frames' energy. Clean studio and telephone prompts measure 25-80 dB, speech under noise at 10 dB SNR
    about 15, at 5 dB about 11."""
    count = len(audio) // HOP
    if count == 0:
        return 0.0
    energy = np.empty(count)
    for s in range(0, count, 1 << 14):  # a block of frames at a time: no float64 copy of a long clip
        frames = audio[s * HOP:min(s + (1 << 14), count) * HOP].reshape(-1, HOP).astype(np.float64)
        energy[s:s + len(frames)] = (frames ** 2).mean(1) + 1e-12
    return float(10 * np.log10(np.percentile(energy, 90) / np.percentile(energy, 10)))


# The mismatch check's bound on the median word's score gap (`judge`), by how clean the speech is:
# 16 from 20 dB up (matching transcripts of clean speech stay under 6 on recorded prompts, 15.5 at most on
# synthetic voices; swapped ones mostly score 15-60), 25 at 15 dB and below (noise widens both: matching
# ones reach 30-37 at 5-10 dB SNR), linear in between; 25 for lines of fewer than 3 words, whose median is one
# or two words. benchmarks/bench_mismatch.py and benchmarks/calibrate_mismatch.py measure it.
CLEAN_WORD_GAP, NOISY_WORD_GAP = 16.0, 25.0
CLEAN_SNR_DB, NOISY_SNR_DB = 20.0, 15.0
# Speech in another language, its words' phones mapped to English ones (facegen.languages): on synthetic
# speech in 22 languages (benchmarks/bench_languages.py; the held-out nl, pl, tr not looked at) matching
# transcripts reach 16.2, swapped ones mostly 20-60 (a few 16-18, most of those refused by the other sign)
FOREIGN_WORD_GAP = 20.0
SHORT_LINE_WORDS = 3


def word_gap_bound(snr_db: float, words: int) -> float:
    """The largest median word score gap a matching transcript has at this SNR (see above)."""
    if words < SHORT_LINE_WORDS:
        return NOISY_WORD_GAP
    clean = min(max((snr_db - NOISY_SNR_DB) / (CLEAN_SNR_DB - NOISY_SNR_DB), 0.0), 1.0)
    return NOISY_WORD_GAP + (CLEAN_WORD_GAP - NOISY_WORD_GAP) * clean


# Both signs halfway: over 15 % of the speech outside the words and a median gap over 8 — no matching script
# of the recorded prompts (odd half) or of the synthetic voices, clean or noisy, does both; swapped ones that
# pass the single bounds often do.
PART_UNEXPLAINED, PART_WORD_GAP = 0.15, 8.0


def left_out(loud: np.ndarray, words: list[tuple[str, int, int]]) -> str:
    """Where the speech the words leave out lies: at the start, at the end or in the middle (the most)."""
    outside = loud.copy()
    for _, first, last in words:
        outside[first:last + 1] = False
    first, last = (words[0][1], words[-1][2]) if words else (len(loud), len(loud))
    parts = {"at the start": outside[:first].sum(), "at the end": outside[last + 1:].sum(),
             "in the middle": outside[first:last + 1].sum()}
    return max(parts, key=parts.get)


@dataclass(frozen=True)
class Match:
    """How well a transcript matches its speech: the share of the loud frames outside its words
    (`unexplained`), the median word's score gap over the free phone loop (`word_gap`; NaN when no scored
    piece held a word) and its bound at this line's SNR (`gap_bound`); `problem`: why it does not match (None:
    it does)."""

    unexplained: float
    word_gap: float
    gap_bound: float
    problem: str | None = None

    @property
    def score(self) -> float:
        """One number to sort lines by: 1 - (the worst sign over its bound) / 2, in [0, 1]; 0.5 is the bound,
        a line below it is refused (or flagged)."""
        gap = 0.0 if math.isnan(self.word_gap) else self.word_gap
        worst = max(self.unexplained / MAX_UNEXPLAINED, gap / self.gap_bound,
                    min(self.unexplained / PART_UNEXPLAINED, gap / PART_WORD_GAP))
        return round(min(max(1.0 - worst / 2, 0.0), 1.0), 3)

    def as_dict(self) -> dict:
        """For reports and metadata (JSON): the score, both signs, the bound, the problem."""
        return {"score": self.score, "unexplained": round(self.unexplained, 4),
                "word_gap": None if math.isnan(self.word_gap) else round(self.word_gap, 2),
                "word_gap_bound": round(self.gap_bound, 2), "problem": self.problem}


UNALIGNED = "no alignment of its words to the audio exists"


def unaligned() -> Match:
    """The Match of a transcript whose words cannot be placed in the speech at all (score 0)."""
    return Match(1.0, float("nan"), CLEAN_WORD_GAP, UNALIGNED)


def is_mismatch(exc: Exception) -> bool:
    """Whether `exc` is the refusal of a transcript that does not match its speech (`mismatch`)."""
    return isinstance(exc, FacegenError) and str(exc).startswith("the transcript does not match the speech")


def mismatch(detail: str) -> FacegenError:
    """The refusal of a transcript that does not match the speech."""
    return FacegenError(f"the transcript does not match the speech ({detail}): check the transcript",
                        param="text")


def judge(loud: np.ndarray, words: list[tuple[str, int, int]], gaps: np.ndarray, free: np.ndarray,
          snr_db: float = 0.0, foreign: bool = False) -> Match:
    """The Match of an alignment's words (frames of 10 ms; `loud`: align_pieces.loud_frames; `gaps` and
    `free`: per frame, the alignment's and the free phone loop's state gaps, NaN outside the scored
    pieces); `foreign`: a language other than English, whose phones the English model hears less well (its
    bound at least FOREIGN_WORD_GAP)."""
    unexplained, excess = match_scores(loud, words, gaps, free)
    bound = max(word_gap_bound(snr_db, len(words)), FOREIGN_WORD_GAP if foreign else 0.0)
    problem = None
    if unexplained > MAX_UNEXPLAINED:
        problem = f"{unexplained:.0%} of the speech lies outside its words, {left_out(loud, words)}"
    elif excess > bound:
        problem = f"its words fit the sounds poorly, score gap {excess:.0f} > {bound:.0f}"
    elif unexplained > PART_UNEXPLAINED and excess > PART_WORD_GAP:  # both halfway: another line's script
        problem = (f"{unexplained:.0%} of the speech lies outside its words, {left_out(loud, words)}, "
                   f"and they fit the sounds poorly (score gap {excess:.0f})")
    return Match(unexplained, excess, bound, problem)


def match_scores(loud: np.ndarray, words: list[tuple[str, int, int]], gaps: np.ndarray,
                 free: np.ndarray) -> tuple[float, float]:
    """The two signs `judge` bounds: the share of loud frames outside the words, and the median word's
    score gap over the free phone loop (NaN when no scored piece holds a word)."""
    in_words = np.zeros(len(loud), bool)
    for _, first, last in words:
        in_words[first:last + 1] = True
    unexplained = float(np.sum(loud & ~in_words)) / max(int(np.sum(loud)), 1)
    excess = [gaps[f:l + 1].mean() - free[f:l + 1].mean() for _, f, l in words]
    return unexplained, float("nan") if np.all(np.isnan(excess)) else float(np.nanmedian(excess))
