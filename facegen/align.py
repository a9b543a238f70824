"""Word timing with pocketsphinx: forced alignment of a transcript, and recognition without one.

What the recogniser hears comes from `facegen.words.normalize_transcript` (lower case, numbers spelled
out, stage directions left out), and every result maps back to the user's words. Words missing from
pocketsphinx's dictionary get a pronunciation from libespeak-ng (`facegen.espeak.pronounce`); a word written
in capitals may also be said letter by letter ("IAX", "SIP"): the search picks the one said.
The first word's start and the last word's end come from the audio (`facegen.align_pieces.speech_edges`).

Long audio is aligned piece by piece, cut at pauses (`facegen.align_pieces`; a piece that fails is retried
alone with wide beams). Every pass subtracts the whole clip's cepstral mean and starts with a fresh noise
estimate, so results never depend on earlier calls; each piece re-aligns the word before it, so the pieces
give the words and phones of one search over the clip.
"""

from __future__ import annotations

import os
import re
import tempfile
import threading
import unicodedata
import warnings

import numpy as np

from facegen.align_pieces import (
    HOP,
    LOOKAHEAD,
    LOOKBEHIND,
    PART_UNEXPLAINED,
    PART_WORD_GAP,
    RATE,
    left_out,
    loud_frames,
    pieces,
    prefix_grammar,
    scored,
    speech_edges,
    speech_snr_db,
    word_gap_bound,
    word_window,
)
from facegen.audio import resample
from facegen.errors import FacegenError
from facegen.espeak import pronounce
from facegen.phonetics import SIL, is_filler
from facegen.words import Word, check_word_rate, no_words, normalize_transcript, spelled

FRAME = 0.01  # pocketsphinx frame step (s)

_LOCK = threading.RLock()
_DECODERS: dict[str, object] = {}
_PRONOUNCED: dict[int, set[str]] = {}  # id(decoder) → words whose espeak pronunciation is in its dictionary
# Alignment tries these in turn until every word is placed. bestpath=False: the lattice pass after the
# FSG search drops valid alignments. Wide beams rescue noisy speech (the search is constrained by the
# transcript, so they stay affordable); fillers (noise/breath models) sometimes derail it.
_WIDE = {"beam": 1e-120, "wbeam": 1e-100, "pbeam": 1e-120, "maxhmmpf": -1}
# Pieces of a clip are aligned with the whole clip's cepstral mean (as one search over the clip would be):
# "cmn" finds it (batch mean, the model's default; its one-word search costs little), and the aligning
# decoders subtract it as given ("live" mode, set before each pass). A model's feat.params overrides what a
# Decoder is given (the en-us model says "-cmn batch": each piece would subtract its own mean, and the words
# near a cut move by up to half a second), so "live" reaches pocketsphinx through a copy of it (_decoder).
_ALIGN = {"lm": None, "bestpath": False, "cmn": "live"}
# The mismatch check's free phone loop ("phone-loop", _free_gaps) scores the acoustic model on every third
# frame only (ds=3, the scores reused in between: half the time of every frame); the words and phones of an
# alignment always come from every frame. Neither it nor "cmn" needs the 130,000-word dictionary (a tenth of a
# second to load).
_CONFIGS = {
    "align": _ALIGN,
    "align-wide": {**_ALIGN, **_WIDE},
    "align-nofiller": {**_ALIGN, "fsgusefiller": False, **_WIDE},
    "phone-loop": {**_ALIGN, "ds": 3, "dict": os.devnull},
    "cmn": {"lm": None, "bestpath": False, "fsgusefiller": False, "ds": 10, "dict": os.devnull},  # features
    "recognize": {},
}
# A transcript that does not match the speech (see _check_match): more than this share of the loud frames
# left outside its words, or a median word fitting the sounds worse than the best free phone sequence
# (per-frame gap to the best HMM state, pocketsphinx's log units) by more than align_pieces.word_gap_bound.
MAX_UNEXPLAINED = 0.3


def _decoder(kind: str):
    if kind not in _DECODERS:
        import pocketsphinx

        try:
            decoder = _new_decoder(pocketsphinx, _CONFIGS[kind])
            if kind == "phone-loop":
                decoder.add_allphone_file("_phones", None)
            elif kind == "cmn":
                decoder.add_word("a", "AH", True)
        except (RuntimeError, ValueError) as exc:
            raise FacegenError(f"cannot start pocketsphinx ({exc}): reinstall it with "
                               "`pip install --force-reinstall pocketsphinx`") from exc
        except OSError as exc:  # the temporary copy of feat.params (_new_decoder)
            raise FacegenError(f"cannot write pocketsphinx's settings to a temporary folder ({exc}): set "
                               "TMPDIR to a writable folder") from exc
        _DECODERS[kind] = decoder
    return _DECODERS[kind]


def _new_decoder(pocketsphinx, config: dict):
    """A pocketsphinx Decoder with `config`, its cepstral mean mode included: the acoustic model's feat.params
    with that mode, in a temporary file it reads once (pocketsphinx lets a model's feat.params override the
    Decoder's own arguments)."""
    cmn = config.get("cmn")
    if cmn is None:
        return pocketsphinx.Decoder(samprate=RATE, loglevel="FATAL", **config)
    with open(os.path.join(pocketsphinx.Config(**config)["hmm"], "feat.params"), encoding="utf-8") as file:
        lines = [line for line in file.read().splitlines() if not line.startswith("-cmn ")]
    with tempfile.TemporaryDirectory(prefix="facegen-align-") as folder:
        params = os.path.join(folder, "feat.params")
        with open(params, "w", encoding="utf-8") as file:
            file.write("\n".join([*lines, f"-cmn {cmn}", ""]))
        decoder = pocketsphinx.Decoder(samprate=RATE, loglevel="FATAL", featparams=params, **config)
    if decoder.config["cmn"] != cmn:
        raise RuntimeError(f"the decoder's cepstral mean mode is {decoder.config['cmn']}, not {cmn}")
    return decoder


def warm() -> None:
    """Create the decoders every alignment uses now (the acoustic model and the 130,000-word dictionary: ~0.18
    s), e.g. in a process that forks workers; pocketsphinx starts no threads, so they fork safely."""
    with _LOCK:
        for kind in ("align", "phone-loop", "cmn"):
            _decoder(kind)


def _dictionary_word(decoder, token: str, letters: list[str] | None = None) -> str:
    """The decoder's dictionary entry for `token`, said as a word or (`letters`: the dictionary's letter
    words, `facegen.words.spelled`) letter by letter.

    A word missing from the dictionary gets espeak's pronunciation; a known word gets it as an
    alternative when it differs, so a quirk of either (CMUdict's "hmm" = HH M) does not derail it. With
    `letters`, an entry of its own ("sip_spelled") holds these and the letters' pronunciation: the search
    picks the one said ("SIP": S IH P or EH S AY P IY), and the plain word is left as it was.
    New words go in without rebuilding the searches: set_align_text builds a fresh one.
    """
    key = unicodedata.normalize("NFKD", token).encode("ascii", "ignore").decode()
    key = re.sub(r"[^a-z0-9']", "", key.lower()).strip("'") or "oov_" + "_".join(f"{ord(c):x}" for c in token)
    spelling = [decoder.lookup_word(letter) for letter in letters or []]
    name = f"{key}_spelled" if spelling and all(spelling) else key
    done = _PRONOUNCED.setdefault(id(decoder), set())
    if name in done:
        return name
    known = _pronunciations(decoder, key)
    wanted = [*known, " ".join(pronounce(token) or ["AH"])] + ([" ".join(spelling)] if name != key else [])
    have = known if name == key else []
    for phones in dict.fromkeys(wanted):
        if phones not in have:
            have.append(phones)
            decoder.add_word(name if len(have) == 1 else f"{name}({len(have)})", phones, False)
    done.add(name)
    return name


def _pronunciations(decoder, key: str) -> list[str]:
    """The dictionary's pronunciations of `key`: its entry and the alternatives "key(2)", "key(3)", ..."""
    known: list[str] = []
    while (pron := decoder.lookup_word(key if not known else f"{key}({len(known) + 1})")) is not None:
        known.append(pron)
    return known


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
        audio = resample(audio, sample_rate, RATE)
    return audio


def _pcm_bytes(audio: np.ndarray) -> bytes:
    """16-bit PCM at a standard level, over a faint noise floor: digital silence derails pocketsphinx."""
    level = float(np.percentile(np.abs(audio), 99.5)) or float(np.max(np.abs(audio)))
    x = audio * (0.5 / level)
    x = x + np.random.default_rng(0).normal(0.0, 1e-3, len(x)).astype(np.float32)
    return (np.clip(x, -1.0, 1.0) * 32767).astype("<i2").tobytes()


def _decode(decoder, pcm: bytes, cmn: str | None = None) -> list[tuple[str, int, int]]:
    """Run one utterance (with the cepstral mean `cmn`, if given); return its segments (word, first frame,
    last frame inclusive). The noise estimate starts afresh, so a result never depends on what the decoder
    heard before (pocketsphinx keeps it across utterances; start_stream resets it)."""
    if cmn is not None:
        decoder.set_cmn(cmn)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # "unnecessary", but the only reset there is
        decoder.start_stream()
    decoder.start_utt()
    decoder.process_raw(pcm, no_search=False, full_utt=True)
    decoder.end_utt()
    return [(s.word, s.start_frame, s.end_frame) for s in (decoder.seg() or [])]


def _base(word: str) -> str:
    return re.sub(r"\(\d+\)$", "", word)


def _clip_cmn(pcm: bytes) -> str:
    """The cepstral mean of the whole clip (pocketsphinx's batch mean, as a string for set_cmn)."""
    decoder = _decoder("cmn")
    decoder.set_align_text("a")
    _decode(decoder, pcm)
    return decoder.get_cmn()


def _state_pass(decoder, pcm: bytes, cmn: str):
    """pocketsphinx's second, state-level alignment pass over the word alignment it has just found."""
    decoder.set_alignment()
    _decode(decoder, pcm, cmn)
    alignment = decoder.get_alignment()
    if alignment is None:
        raise _mismatch("pocketsphinx found no phone alignment for its words")
    return alignment


def _state_gaps(alignment, n_frames: int) -> np.ndarray:
    """Per frame: how far the alignment's HMM state scores below the best state of that frame."""
    gaps = np.zeros(n_frames)
    for phone in alignment.phones():
        if phone.duration > 0:
            gaps[phone.start:phone.start + phone.duration] = -phone.score / phone.duration
    return gaps


def _free_gaps(pcm: bytes, n_frames: int, cmn: str) -> np.ndarray | None:
    """Per frame: how far the best unconstrained phone sequence scores below the best HMM state of that frame
    (its phone's acoustic score over its frames): the fit a matching transcript nearly reaches."""
    decoder = _decoder("phone-loop")
    decoder.activate_search("_phones")
    if not _decode(decoder, pcm, cmn):
        return None
    gaps = np.zeros(n_frames)
    for phone in decoder.seg():  # ascore is a probability; logmath.log gives pocketsphinx's log units back
        gaps[phone.start_frame:phone.end_frame + 1] = -decoder.logmath.log(phone.ascore) / (
            phone.end_frame - phone.start_frame + 1)
    return gaps


def _mismatch(detail: str) -> FacegenError:
    return FacegenError(f"the transcript does not match the speech ({detail}): check the transcript",
                        param="text")


def unknown_share(transcript: str) -> float:
    """The share of the transcript's words pocketsphinx's English dictionary lacks (the recogniser's: the
    aligners' dictionaries gain the words they are given)."""
    tokens = [t for _, said in normalize_transcript(transcript) for t in said]
    with _LOCK:
        return sum(_decoder("recognize").lookup_word(t) is None for t in tokens) / max(len(tokens), 1)


def _check_match(loud: np.ndarray, words: list[tuple[str, int, int]], gaps: np.ndarray,
                 free: np.ndarray, snr_db: float = 0.0) -> None:
    """Raise if the alignment shows that the transcript is not what was said. Two signs:
    - speech the transcript does not explain is left to silence/noise segments: more than MAX_UNEXPLAINED of
      the loud frames outside the words (matching transcripts of recorded prompts: 0.25 at most);
    - words forced onto sounds they are not fit them badly: the median word's state gap over the free phone
      loop above align_pieces.word_gap_bound (16 for clean speech, 25 under noise at 15 dB SNR and below);
    and both halfway (PART_UNEXPLAINED, PART_WORD_GAP): no matching script measured does that.
    Measured: benchmarks/bench_mismatch.py (Asterisk's recorded English prompts, 8 kHz, the odd half: 275/275
    matching scripts pass, 100/105 swapped rows refused) and benchmarks/calibrate_mismatch.py (synthetic
    voices clean and at 10 and 5 dB SNR: matching refused 0/20 clean, 2/60 at 10 dB, 7/60 at 5 dB).
    `gaps` and `free` are NaN outside the pieces scored (align_pieces.scored): their words are left out.
    """
    unexplained, excess = match_scores(loud, words, gaps, free)
    if unexplained > MAX_UNEXPLAINED:
        raise _mismatch(f"{unexplained:.0%} of the speech lies outside its words, {left_out(loud, words)}")
    bound = word_gap_bound(snr_db, len(words))
    if excess > bound:
        raise _mismatch(f"its words fit the sounds poorly, score gap {excess:.0f} > {bound:.0f}")
    if unexplained > PART_UNEXPLAINED and excess > PART_WORD_GAP:  # both signs halfway: another line's script
        raise _mismatch(f"{unexplained:.0%} of the speech lies outside its words, {left_out(loud, words)}, "
                        f"and they fit the sounds poorly (score gap {excess:.0f})")


def match_scores(loud: np.ndarray, words: list[tuple[str, int, int]], gaps: np.ndarray,
                 free: np.ndarray) -> tuple[float, float]:
    """The two signs _check_match bounds: the share of loud frames outside the words, and the median word's
    score gap over the free phone loop (NaN when no scored piece holds a word)."""
    in_words = np.zeros(len(loud), bool)
    for _, first, last in words:
        in_words[first:last + 1] = True
    unexplained = float(np.sum(loud & ~in_words)) / max(int(np.sum(loud)), 1)
    excess = [gaps[f:l + 1].mean() - free[f:l + 1].mean() for _, f, l in words]
    return unexplained, float("nan") if np.all(np.isnan(excess)) else float(np.nanmedian(excess))


Phone = tuple[str, float, float]  # (CMU phone, start s, end s)


def align(audio: np.ndarray, sample_rate: int, transcript: str) -> list[Word]:
    """Word start/end times (s) of `transcript` in `audio` (mono, any rate), by forced alignment.

    Returns one Word per written word of the transcript (words made only of punctuation are left
    out), in order, with the user's spelling. Raises FacegenError for an empty transcript, silent or
    too short audio, or a transcript that does not match the speech.
    """
    return _align(audio, sample_rate, transcript, with_phones=False)[0]


def align_phones(audio: np.ndarray, sample_rate: int, transcript: str) -> tuple[list[Word], list[Phone]]:
    """The words of `align` and the phones inside them: (CMU phone without stress, start, end) in seconds,
    pauses left out — pocketsphinx's phone alignment of the same search (a second pass over the audio)."""
    return _align(audio, sample_rate, transcript, with_phones=True)


def _align(audio: np.ndarray, sample_rate: int, transcript: str,
           with_phones: bool) -> tuple[list[Word], list[Phone]]:
    entries = normalize_transcript(transcript)
    if not entries:
        raise no_words(transcript)
    # (its word's index, token, its letters when it may be said letter by letter)
    spoken = [(i, token, spelled(word, token)) for i, (word, tokens) in enumerate(entries)
              for token in tokens]
    check_word_rate(len(spoken), len(audio) / sample_rate, "the transcript")  # "1234": four words said
    audio = _pcm16k(audio, sample_rate)
    pcm = _pcm_bytes(audio)
    duration = len(audio) / RATE
    n_frames = len(audio) // HOP
    loud = loud_frames(audio, n_frames)
    spans = pieces(loud)
    chosen = scored(spans)
    words: list[tuple[str, int, int]] = []
    phones: list[list[Phone]] = []  # per word, with_phones
    gaps, free = np.full(n_frames, np.nan), np.full(n_frames, np.nan)
    with _LOCK:
        cmn = _clip_cmn(pcm)
        start, p = 0, 0
        while p < len(spans) and len(words) < len(spoken):
            last = p == len(spans) - 1
            cut = spans[p][1]
            stop = n_frames if last else min(n_frames, cut + LOOKAHEAD)
            # the piece before's last word, aligned again: LOOKBEHIND in align_pieces
            back = 1 if words else 0
            origin = max(0, words[-1][1] - LOOKBEHIND) if words else 0  # the first frame of its search
            part = pcm[origin * HOP * 2:stop * HOP * 2]
            found = _align_piece(part, [(t, s) for _, t, s in spoken[len(words) - back:]], stop - origin,
                                 n_frames - origin, cmn, prefix=not last)
            if found is None or len(found[1]) <= back:
                if last:
                    raise _mismatch("no alignment of its words to the audio exists")
                chosen = {i for i in chosen if i < p} | ({p} if any(i >= p for i in chosen) else set())
                # a piece whose words cannot be told apart: align the rest at once
                spans[p:] = [(start, n_frames)]
                continue
            decoder, segments = found
            kept = segments[back:] if last else [s for s in segments[back:] if s[1] < cut - origin]
            if kept and words and kept[0][1] + origin <= words[-1][2]:  # never before the word before ends
                kept[0] = (kept[0][0], words[-1][2] + 1 - origin, max(kept[0][2], words[-1][2] + 1 - origin))
            end = n_frames if last else max(cut, origin + (kept[-1][2] + 1 if kept else 0))
            if kept and (with_phones or p in chosen):
                alignment = _piece_states(decoder, part, segments[:back + len(kept)], end - origin, cmn, last)
                if with_phones:
                    phones += _phones(alignment, back, len(kept), origin, duration)
                if p in chosen:
                    n = min(decoder.n_frames() + origin, end) - start
                    gaps[start:start + n] = _state_gaps(alignment, decoder.n_frames())[start - origin:][:n]
                    piece_free = _free_gaps(pcm[start * HOP * 2:end * HOP * 2], n, cmn)
                    free[start:start + n] = gaps[start:start + n] if piece_free is None else piece_free[:n]
            words += [(w, a + origin, b + origin) for w, a, b in kept]
            start, p = end, p + 1
    if len(words) < len(spoken):
        raise _mismatch("no alignment of its words to the audio exists")
    # the outer edges from the audio (align_pieces.speech_edges); a word whose edge moves is scored over its
    # new bounds as the search placed them (the frames it gave to silence fit worse), and its phones come from
    # aligning it again inside them
    first, last = words[0][1], words[-1][2]
    start, end = speech_edges(loud, first, last)
    words[0] = (words[0][0], start, words[0][2])
    words[-1] = (words[-1][0], words[-1][1], end)
    _check_match(loud, words, gaps, free, speech_snr_db(audio))
    moved = {k for k, edge in ((0, start != first), (len(words) - 1, end != last))
             if edge and with_phones and len(phones) == len(words)}
    for k in moved:
        with _LOCK:
            alignment = _word_alone(pcm, spoken[k][1:], words[k][1], words[k][2] + 1, cmn)
            again = [] if alignment is None else _phones(alignment, 0, 1, words[k][1], duration)
            phones[k] = again[0] if again else phones[k]
    times: dict[int, list[float]] = {}
    for (index, _, _), (_, first, last) in zip(spoken, words, strict=True):
        start, end = first * FRAME, min((last + 1) * FRAME, duration)
        times.setdefault(index, [start, end])[1] = end
    return ([Word(entries[i][0], round(t[0], 3), round(t[1], 3)) for i, t in sorted(times.items())],
            [phone for word in phones for phone in word])


def _word_alone(pcm: bytes, token: tuple[str, list[str] | None], first: int, end: int, cmn: str):
    """The state alignment of the clip's first or last word (`token` and its letters) over its frames `first`
    to `end` (excluded), whose outer edge came from the audio (align_pieces.speech_edges): aligned again over
    just those frames, without silence, so that its sounds share them as said (the /s/ of "six" its 150 ms,
    not one frame); None if pocketsphinx finds none."""
    decoder = _decoder("align-nofiller")
    decoder.set_align_text(_dictionary_word(decoder, *token))
    part = pcm[first * HOP * 2:end * HOP * 2]
    if not _decode(decoder, part, cmn):
        return None
    try:
        return _state_pass(decoder, part, cmn)
    except (FacegenError, RuntimeError):
        return None


def _align_piece(pcm: bytes, tokens: list[tuple[str, list[str] | None]], length: int, rest: int, cmn: str,
                 prefix: bool) -> tuple[object, list[tuple[str, int, int]]] | None:
    """Align one piece: all of `tokens` (each with its letters, if it may be spelled), or (`prefix`) as many
    of the first of them as its speech holds.

    Tries the decoders of _CONFIGS in turn (wide beams only when the first fails; a prefix never without
    fillers, it would have nothing else for a pause); returns the decoder that aligned it (its search still
    holds the alignment) and the words (dictionary word, first frame, last frame in the piece), or None.
    A prefix that takes every word it was offered is offered them all.
    """
    offers = [word_window(len(tokens), length, rest), len(tokens)] if prefix else [len(tokens)]
    for kind in ("align", "align-wide") if prefix else ("align", "align-wide", "align-nofiller"):
        decoder = _decoder(kind)
        for offered in offers:
            keys = [_dictionary_word(decoder, token, letters) for token, letters in tokens[:offered]]
            if prefix:
                decoder.add_fsg("_prefix", prefix_grammar(decoder, "_prefix", keys))
                decoder.activate_search("_prefix")
            else:
                decoder.set_align_text(" ".join(keys))
            words = [s for s in _decode(decoder, pcm, cmn) if not is_filler(s[0])]
            said = [_base(w) for w, _, _ in words]
            if said == keys or (prefix and words and said == keys[:len(said)]):
                if len(said) < offered or offered == len(tokens):
                    return decoder, words
            elif not prefix or not words:
                break
    return None


def _piece_states(decoder, pcm: bytes, kept: list[tuple[str, int, int]], length: int, cmn: str, last: bool):
    """The state alignment of a piece (`pcm`, its lookbehind and lookahead included) whose words `decoder` has
    just aligned; `kept`: its words up to the cut (the lookbehind's word first).

    The state pass follows all the words the search placed, those of the lookahead too, over the audio they
    cover: the words at the cut get the phones of one search over the clip. The search may have stopped inside
    the lookahead's last word, which the state pass then cannot place (pocketsphinx: "Failed to stop utterance
    processing"); then the kept words are aligned again alone, over the piece's first `length` frames."""
    if not last:
        covered = max(s.end_frame for s in decoder.seg()) + 1
        try:
            return _state_pass(decoder, pcm[:covered * HOP * 2], cmn)
        except RuntimeError:
            pcm = pcm[:length * HOP * 2]
            decoder.set_align_text(" ".join(w for w, _, _ in kept))
            _decode(decoder, pcm, cmn)
    return _state_pass(decoder, pcm, cmn)


def _phones(alignment, skip: int, count: int, first: int, duration: float) -> list[list[Phone]]:
    """The phones of `count` words of a piece's state alignment after its first `skip` words (`first`: the
    frame the piece's search started at). Read while iterating: an entry of pocketsphinx's alignment is only
    valid while its iterator is."""
    phones: list[list[Phone]] = []
    for word in alignment:
        if count == 0:
            break
        if is_filler(word.name):
            continue
        if skip:
            skip -= 1
            continue
        count -= 1
        phones.append([(phone.name, round((first + phone.start) * FRAME, 3),
                        round(min((first + phone.start + phone.duration) * FRAME, duration), 3))
                       for phone in word if phone.name != SIL])
    return phones


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
            for w, first, last in segments if not is_filler(w)]
