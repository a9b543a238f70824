"""Speech recognition without a transcript: pocketsphinx's default US English model hears the words (less
accurate than forced alignment of a transcript, facegen.align; their timing is usually close)."""

from __future__ import annotations

import numpy as np

from facegen.align_pieces import RATE
from facegen.phonetics import is_filler
from facegen.sphinx import FRAME, LOCK, base_word, decode, get_decoder, pcm16k, pcm_bytes
from facegen.words import Word


def recognize(audio: np.ndarray, sample_rate: int) -> list[Word]:
    """Words recognised in `audio` without a transcript (pocketsphinx's default US English model).

    Less accurate than `align` with a transcript: words may be wrong; their timing is usually close.
    """
    audio = pcm16k(audio, sample_rate)
    pcm = pcm_bytes(audio)
    with LOCK:
        segments = decode(get_decoder("recognize"), pcm)
    duration = len(audio) / RATE
    return [Word(base_word(w), round(first * FRAME, 3), round(min((last + 1) * FRAME, duration), 3))
            for w, first, last in segments if not is_filler(w)]
