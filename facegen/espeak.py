"""libespeak-ng (via ctypes): speech synthesis with the true word and phone timings, grapheme-to-phoneme
(`phonemize`) and a word's pocketsphinx (CMU) phones (`pronounce`, through facegen.phonetics' table).

The library comes from the PyPI package `espeakng-loader` and is loaded once per process. It is not
thread-safe, so every call into it holds one lock.
"""

from __future__ import annotations

import ctypes
import itertools
import os
import re
import threading
from dataclasses import dataclass, field

import numpy as np

from facegen.audio import resample
from facegen.errors import FacegenError
from facegen.phonetics import espeak_to_cmu
from facegen.words import Word, strip_edges

# speak_lib.h constants
_AUDIO_OUTPUT_SYNCHRONOUS = 2
_INITIALIZE_PHONEME_EVENTS = 0x0001
_INITIALIZE_DONT_EXIT = 0x8000
_POS_CHARACTER = 1
_CHARS_UTF8 = 1
_EVENT_LIST_TERMINATED, _EVENT_WORD, _EVENT_PHONEME = 0, 1, 7
_PARAM_RATE, _PARAM_PITCH = 1, 3
_PHONEMES_IPA = 0x02  # espeak_TextToPhonemes: IPA instead of mnemonics


class _EventId(ctypes.Union):
    _fields_ = [("number", ctypes.c_int), ("name", ctypes.c_char_p), ("string", ctypes.c_char * 8)]


class _Event(ctypes.Structure):
    _fields_ = [
        ("type", ctypes.c_int),
        ("unique_identifier", ctypes.c_uint),
        ("text_position", ctypes.c_int),
        ("length", ctypes.c_int),
        ("audio_position", ctypes.c_int),
        ("sample", ctypes.c_int),
        ("user_data", ctypes.c_void_p),
        ("id", _EventId),
    ]


_Callback = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int,
                             ctypes.POINTER(_Event))


@dataclass
class Phone:
    """One phone: `text` is espeak's phoneme mnemonic (stress marks kept), times in seconds."""

    text: str
    start: float
    end: float
    word: int  # index into Speech.words


@dataclass
class Speech:
    """Synthesised speech: mono float32 audio with the synthesiser's own word and phone timings."""

    audio: np.ndarray
    sample_rate: int
    words: list[Word] = field(default_factory=list)
    phones: list[Phone] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return len(self.audio) / self.sample_rate


class _Espeak:
    """The loaded library and the state of the synthesis in progress (guarded by `lock`)."""

    def __init__(self) -> None:
        import espeakng_loader

        self.lock = threading.RLock()
        try:
            lib = ctypes.CDLL(espeakng_loader.get_library_path())
            data = espeakng_loader.get_data_path()
        except (OSError, RuntimeError) as exc:
            raise FacegenError(f"cannot load libespeak-ng ({exc}): reinstall it with "
                               "`pip install --force-reinstall espeakng-loader`") from exc
        lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
        lib.espeak_Initialize.restype = ctypes.c_int
        lib.espeak_SetSynthCallback.argtypes = [_Callback]
        lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
        lib.espeak_SetVoiceByName.restype = ctypes.c_int
        lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
        lib.espeak_SetParameter.restype = ctypes.c_int
        lib.espeak_Synth.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint, ctypes.c_int,
                                     ctypes.c_uint, ctypes.c_uint, ctypes.c_void_p, ctypes.c_void_p]
        lib.espeak_Synth.restype = ctypes.c_int
        lib.espeak_TextToPhonemes.argtypes = [ctypes.POINTER(ctypes.c_char_p), ctypes.c_int, ctypes.c_int]
        lib.espeak_TextToPhonemes.restype = ctypes.c_char_p
        lib.espeak_ng_SetRandSeed.argtypes = [ctypes.c_long]
        lib.espeak_ng_SetRandSeed.restype = None
        rate = lib.espeak_Initialize(_AUDIO_OUTPUT_SYNCHRONOUS, 0, os.fsencode(data),
                                     _INITIALIZE_PHONEME_EVENTS | _INITIALIZE_DONT_EXIT)
        if rate <= 0:
            raise FacegenError(f"libespeak-ng failed to initialise with data {data}: "
                               "reinstall it with `pip install --force-reinstall espeakng-loader`")
        self.lib = lib
        self.sample_rate = rate
        self.chunks: list[np.ndarray] = []
        self.events: list[tuple[int, int, int, str]] = []  # (type, sample, text_position, phoneme)
        self._callback = _Callback(self._collect)  # keep a reference: the library holds the pointer
        lib.espeak_SetSynthCallback(self._callback)
        self.voice: str | None = None

    def _collect(self, wav, n: int, events) -> int:
        if n > 0:
            self.chunks.append(np.ctypeslib.as_array(wav, (n,)).copy())
        i = 0
        while events[i].type != _EVENT_LIST_TERMINATED:
            ev = events[i]
            if ev.type in (_EVENT_WORD, _EVENT_PHONEME):
                name = ev.id.string.decode("ascii", "replace") if ev.type == _EVENT_PHONEME else ""
                self.events.append((ev.type, ev.sample, ev.text_position, name))
            i += 1
        return 0  # 0 = continue synthesis

    def set_voice(self, voice: str) -> None:
        if voice != self.voice:
            if self.lib.espeak_SetVoiceByName(voice.encode()) != 0:
                self.voice = None
                raise FacegenError(f"unknown espeak voice {voice!r}: use a language code with an optional "
                                   "variant, e.g. 'en-us', 'en', 'en-us+f3', 'en+m2'")
            self.voice = voice


_ESPEAK: _Espeak | None = None
_INIT_LOCK = threading.Lock()


def espeak() -> _Espeak:
    """The process-wide libespeak-ng instance (loaded and initialised on first use)."""
    global _ESPEAK
    if _ESPEAK is None:
        with _INIT_LOCK:
            if _ESPEAK is None:
                _ESPEAK = _Espeak()
    return _ESPEAK


def synthesize(text: str, voice: str = "en-us", pitch: int = 50, rate: int = 170,
               variant: str | None = None, sample_rate: int | None = None) -> Speech:
    """Speak `text` with libespeak-ng; return audio with the true word and phone times in seconds.

    `voice` is an espeak voice name, optionally with a variant ("en-us+f3"); `variant` adds one
    ("m2", "f3", ...). `pitch` is 0-100, `rate` in words per minute (80-450). The audio is at espeak's
    native 22050 Hz unless `sample_rate` asks for another rate (times are unaffected).
    Words are the whitespace-separated words of `text` (edge punctuation stripped); a word spoken as
    several (e.g. "42" → "forty two") spans all of them; words that are not spoken are left out.
    libespeak-ng keeps some waveform state (pitch flutter) between calls and places phone boundaries
    on pitch periods, so repeating a call can move the times by up to a pitch period (~10 ms).
    """
    if not text.strip():
        raise FacegenError("nothing to synthesise: the text is empty")
    if not 0 <= pitch <= 100:
        raise FacegenError(f"pitch {pitch} is out of range: use 0-100")
    if not 80 <= rate <= 450:
        raise FacegenError(f"rate {rate} is out of range: use 80-450 words per minute")
    name = f"{voice}+{variant}" if variant else voice
    es = espeak()
    with es.lock:
        es.set_voice(name)
        es.lib.espeak_SetParameter(_PARAM_RATE, rate, 0)
        es.lib.espeak_SetParameter(_PARAM_PITCH, pitch, 0)
        es.lib.espeak_ng_SetRandSeed(0)  # for the voices with noise (klatt, whisper)
        es.chunks, es.events = [], []
        data = text.encode("utf-8")
        status = es.lib.espeak_Synth(data, len(data) + 1, 0, _POS_CHARACTER, 0, _CHARS_UTF8, None, None)
        chunks, events = es.chunks, es.events
        es.chunks, es.events = [], []
    if status != 0:
        raise FacegenError(f"libespeak-ng could not synthesise the text (status {status}): simplify the text")
    audio = (np.concatenate(chunks) if chunks else np.zeros(0, np.int16)).astype(np.float32) / 32768.0
    native = es.sample_rate
    words, phones = _timings(text, events, native, len(audio) / native, name)
    _closures_to_stops(phones, audio, native)
    if sample_rate is not None and sample_rate != native:
        audio = resample(audio, native, sample_rate)
    return Speech(audio, sample_rate or native, words, phones)


def _timings(text: str, events: list[tuple[int, int, int, str]], rate: int, duration: float,
             voice: str) -> tuple[list[Word], list[Phone]]:
    """Turn espeak's WORD and PHONEME events into words (mapped to the words of `text`) and phones."""
    tokens = [(m.start(), m.end(), strip_edges(m.group())) for m in re.finditer(r"\S+", text)]
    tokens = [t for t in tokens if t[2]]
    # espeak's sub-words: [token index, start time, [(phone, start, end), ...], end time]
    subs: list[list] = []
    stream: list[tuple[str, float, int]] = []  # every phoneme event: (name, time, sub or -1 for a pause)
    token = 0
    for kind, sample, position, name in events:
        t = sample / rate
        if kind == _EVENT_WORD and tokens:
            char = position - 1  # espeak's text positions count characters from 1
            # the word holding that character, else the next one (positions can point at a space)
            while token + 1 < len(tokens) and (tokens[token + 1][0] <= char or tokens[token][1] <= char):
                token += 1
            subs.append([token, t, [], None])
        elif kind == _EVENT_PHONEME and any(c.isalnum() or c in "@_" for c in name):  # not ";" markers
            pause = name.startswith("_")
            stream.append((name, t, -1 if pause or not subs else len(subs) - 1))
    for i, (name, start, sub) in enumerate(stream):
        end = stream[i + 1][1] if i + 1 < len(stream) else duration
        if sub >= 0 and not subs[sub][2] and _is_stop(name):  # a word's first phone: the silence between
            start = max(subs[sub][1], start - MAX_CLOSURE)       # the word's start and a stop is its closure
        if sub >= 0:
            subs[sub][2].append((name, start, end))
    for i, sub in enumerate(subs):
        limit = subs[i + 1][1] if i + 1 < len(subs) else duration
        sub[3] = min(sub[2][-1][2], limit) if sub[2] else limit

    # espeak sometimes speaks two words as one ("from the"): give the silent words their share of phones
    owner: dict[int, int] = {}  # eventless token → sub that spoke it
    voiced = {sub[0] for sub in subs}
    for tok in range(len(tokens)):
        if tok not in voiced and subs:
            before = [i for i, sub in enumerate(subs) if sub[0] < tok]
            owner[tok] = before[-1] if before else 0
    pieces: list[tuple[int, float, float, list]] = []  # (token, start, end, phones)
    for i, (tok, start, phones, end) in enumerate(subs):
        extra = sorted(t for t, o in owner.items() if o == i)
        if not extra:
            pieces.append((tok, start, end, phones))
            continue
        group = sorted([tok] + extra)
        counts = [len(phonemize(tokens[t][2], voice)) for t in group]
        for t, part in zip(group, _split(phones, counts, group.index(tok))):
            if part:
                part_end = end if part is phones or part[-1] is phones[-1] else part[-1][2]
                pieces.append((t, start if t == tok and part[0] is phones[0] else part[0][1], part_end, part))
    pieces.sort(key=lambda p: p[1])

    words: list[Word] = []
    phone_list: list[Phone] = []
    index: dict[int, int] = {}
    for tok, start, end, phones in pieces:
        if tok in index:
            words[index[tok]].end = max(words[index[tok]].end, end)
        else:
            index[tok] = len(words)
            words.append(Word(tokens[tok][2], start, end))
        phone_list += [Phone(name, s, max(s, min(e, end)), index[tok]) for name, s, e in phones]
    return words, phone_list


MAX_CLOSURE = 0.12  # seconds of silence before a word's first stop that belong to the stop's closure


def _is_stop(name: str) -> bool:
    """An espeak phoneme mnemonic of a stop or affricate (p, b, t, d, k, g, c, q and their variants: tS,
    dZ, ts, t#, kh ...). espeak's event for a word's first stop comes at its release, after the silent closure
    that follows the word's event: the lips (or the tongue) are closed from the word's start, not from the
    burst (a phone alignment of the audio, pocketsphinx's too, puts the closure in the stop)."""
    name = name.lstrip("',%=")
    return bool(name) and name[0] in "pbtdkgcq"


def _closures_to_stops(phones: list[Phone], audio: np.ndarray, rate: int) -> None:
    """Inside a word espeak speaks a stop's silent closure as the end of the phone before it (its event comes
    at the release): move that silence — the phone's last 5 ms frames 25 dB or more below its loudest, at most
    MAX_CLOSURE, leaving it 10 ms — into the stop, in place."""
    hop = rate // 200
    for prev, stop in itertools.pairwise(phones):
        if not _is_stop(stop.text) or prev.word != stop.word or abs(prev.end - stop.start) > 1e-6:
            continue
        a, b = int(prev.start * rate), int(prev.end * rate)
        frames = audio[a: a + (b - a) // hop * hop].reshape(-1, hop).astype(np.float64)
        if len(frames) < 3:
            continue
        db = 10 * np.log10(np.mean(frames**2, axis=1) + 1e-12)
        quiet = db < db.max() - 25
        n = len(quiet) - (np.flatnonzero(~quiet)[-1] + 1)  # the trailing quiet frames
        n = min(n, int(MAX_CLOSURE * 200), len(quiet) - 2)
        if n > 0:
            prev.end = stop.start = prev.end - n * hop / rate


def _split(phones: list, counts: list[int], own: int) -> list[list]:
    """Split one sub-word's phones between the words it spoke, by their phone counts in order."""
    counts = list(counts)
    others = sum(c for i, c in enumerate(counts) if i != own)
    if len(phones) - others >= 1:
        counts[own] = len(phones) - others
    else:  # counts do not fit: share in proportion
        total = max(sum(counts), 1)
        counts = [max(1, round(c * len(phones) / total)) if c else 0 for c in counts]
        counts[own] += len(phones) - sum(counts)
    parts, i = [], 0
    for c in counts:
        parts.append(phones[i:i + max(c, 0)])
        i += max(c, 0)
    return parts


def phonemize(word: str, voice: str = "en-us", ipa: bool = False) -> list[str]:
    """espeak's phonemes (mnemonics, stress marks kept; `ipa`: in the IPA, stress and length marks kept) for
    `word` — a grapheme-to-phoneme step."""
    es = espeak()
    out: list[str] = []
    with es.lock:
        es.set_voice(voice)
        buf = ctypes.c_char_p(word.encode("utf-8"))
        mode = (ord("|") << 8) | (_PHONEMES_IPA if ipa else 0)  # bits 8-23: separator between phoneme names
        while buf.value:
            result = es.lib.espeak_TextToPhonemes(ctypes.byref(buf), _CHARS_UTF8, mode)
            if result is None:
                break
            for chunk in result.decode("utf-8", "replace").split():
                out.extend(p for p in chunk.split("|") if p)
    return out


def pronounce(token: str) -> list[str]:
    """CMU phones for a spoken token, from libespeak-ng's grapheme-to-phoneme rules."""
    return espeak_to_cmu(phonemize(token))
