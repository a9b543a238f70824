"""pocketsphinx's decoders, shared by forced alignment (facegen.align), recognition (facegen.recognition)
and the phones inside given word times (facegen.phone_timing): one decoder per kind of search (_CONFIGS),
built once per process and used under LOCK (a decoder holds one search at a time), the audio as
pocketsphinx hears it (`pcm16k`, `pcm_bytes`), one utterance decoded afresh (`decode`), and the dictionary
entries of a transcript's words (`dictionary_word`).
"""

from __future__ import annotations

import os
import re
import tempfile
import threading
import unicodedata
import warnings

import numpy as np

from facegen.align_pieces import RATE
from facegen.audio import all_finite, peak, resample
from facegen.errors import FacegenError
from facegen.espeak import pronounce
from facegen.words import normalize_transcript

FRAME = 0.01  # pocketsphinx frame step (s)

LOCK = threading.RLock()
DECODERS: dict[str, object] = {}
_PRONOUNCED: dict[int, set[str]] = {}  # id(decoder) → words whose espeak pronunciation is in its dictionary
# Alignment tries these in turn until every word is placed. bestpath=False: the lattice pass after the
# FSG search drops valid alignments. Wide beams rescue noisy speech (the search is constrained by the
# transcript, so they stay affordable); fillers (noise/breath models) sometimes derail it.
_WIDE = {"beam": 1e-120, "wbeam": 1e-100, "pbeam": 1e-120, "maxhmmpf": -1}
# Pieces of a clip are aligned with the whole clip's cepstral mean (as one search over the clip would be):
# "cmn" finds it (batch mean, the model's default; its one-word search costs little), and the aligning
# decoders subtract it as given ("live" mode, set before each pass). A model's feat.params overrides what a
# Decoder is given (the en-us model says "-cmn batch": each piece would subtract its own mean, and the words
# near a cut move by up to half a second), so "live" reaches pocketsphinx through a copy of it (get_decoder).
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
    # long audio, piece by piece (facegen.recognition): the clip's cepstral mean as in alignment, a lighter
    # search (no flat pass; at most 2,000 HMMs and 10 word exits a frame): 4x faster, 3 % fewer words right
    "recognize-long": {"cmn": "live", "fwdflat": False, "maxhmmpf": 2000, "maxwpf": 10},
}


def get_decoder(kind: str):
    if kind not in DECODERS:
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
        DECODERS[kind] = decoder
    return DECODERS[kind]


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
    with LOCK:
        for kind in ("align", "phone-loop", "cmn"):
            get_decoder(kind)


def dictionary_word(decoder, token: str, letters: list[str] | str | None = None) -> str:
    """The decoder's dictionary entry for `token`, said as a word or (`letters`: the dictionary's letter
    words, `facegen.words.spelled`) letter by letter; or (`letters` a language code other than English) said
    in that language: its entry of its own ("pain__fr"), the pronunciation espeak-ng gives it there in the
    IPA mapped to these phones by articulatory features (facegen.phonetics.ipa_to_cmu), English's left out.

    A word missing from the dictionary gets espeak's pronunciation; a known word gets it as an
    alternative when it differs, so a quirk of either (CMUdict's "hmm" = HH M) does not derail it. With
    `letters`, an entry of its own ("sip_spelled") holds these and the letters' pronunciation: the search
    picks the one said ("SIP": S IH P or EH S AY P IY), and the plain word is left as it was.
    New words go in without rebuilding the searches: set_align_text builds a fresh one.
    """
    key = unicodedata.normalize("NFKD", token).encode("ascii", "ignore").decode()
    key = re.sub(r"[^a-z0-9']", "", key.lower()).strip("'") or "oov_" + "_".join(f"{ord(c):x}" for c in token)
    if isinstance(letters, str):
        return _foreign_word(decoder, token, key, letters)
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


def _foreign_word(decoder, token: str, key: str, voice: str) -> str:
    from facegen.espeak import phonemize
    from facegen.phonetics import ipa_to_cmu

    name = f"{key}__{re.sub(r'[^a-z0-9]', '_', voice.lower())}"
    done = _PRONOUNCED.setdefault(id(decoder), set())
    if name not in done:
        decoder.add_word(name, " ".join(ipa_to_cmu(phonemize(token, voice, ipa=True)) or ["AH"]), False)
        done.add(name)
    return name


def _pronunciations(decoder, key: str) -> list[str]:
    """The dictionary's pronunciations of `key`: its entry and the alternatives "key(2)", "key(3)", ..."""
    known: list[str] = []
    while (pron := decoder.lookup_word(key if not known else f"{key}({len(known) + 1})")) is not None:
        known.append(pron)
    return known


def pcm16k(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """Mono float audio at any rate → 16 kHz float32, after the checks a user's audio needs."""
    audio = np.asarray(audio, dtype=np.float32)
    if audio.ndim == 2:  # [samples, channels] or [channels, samples]
        audio = audio.mean(axis=1 if audio.shape[1] < audio.shape[0] else 0)
    if audio.ndim != 1 or sample_rate <= 0:
        raise FacegenError("audio must be a mono signal with a positive sample rate: pass one channel")
    if len(audio) < 0.25 * sample_rate:
        raise FacegenError(f"the audio is too short ({len(audio) / sample_rate:.2f} s): "
                           "use a recording with at least a quarter second of speech")
    if not all_finite(audio):
        raise FacegenError("the audio contains NaN or infinite samples: check the audio file")
    if peak(audio) < 1e-3:
        raise FacegenError("the audio is silent: check the audio file, its channel and its volume")
    if sample_rate != RATE:
        audio = resample(audio, sample_rate, RATE)
    return audio


LEVEL_SAMPLES = 1 << 24  # samples the level is measured on (17 minutes; longer audio: evenly spread ones)


def pcm_bytes(audio: np.ndarray) -> bytearray:
    """16-bit PCM at a standard level, over a faint noise floor: digital silence derails pocketsphinx.
    Made a block at a time, in place (the same bytes: the noise generator's stream does not depend on the
    blocks; no second copy of a long clip's)."""
    spread = audio[::-(-len(audio) // LEVEL_SAMPLES)] if len(audio) > LEVEL_SAMPLES else audio
    level = float(np.percentile(np.abs(spread), 99.5)) or peak(audio)
    noise = np.random.default_rng(0)
    pcm = bytearray(2 * len(audio))
    out = np.frombuffer(pcm, "<i2")
    for s in range(0, len(audio), 1 << 22):
        x = audio[s:s + (1 << 22)] * (0.5 / level)
        x = x + noise.normal(0.0, 1e-3, len(x)).astype(np.float32)
        out[s:s + len(x)] = np.clip(x, -1.0, 1.0) * 32767
    return pcm


def decode(decoder, pcm: bytes, cmn: str | None = None) -> list[tuple[str, int, int]]:
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


def base_word(word: str) -> str:
    return re.sub(r"\(\d+\)$", "", word)


CMN_SECONDS = 60  # longer audio: its cepstral mean from pieces this long (each a short call)


def clip_cmn(pcm: bytes) -> str:
    """The cepstral mean of the whole clip (pocketsphinx's batch mean, as a string for set_cmn); over
    CMN_SECONDS, the mean of its pieces' means weighted by their lengths."""
    decoder = get_decoder("cmn")
    decoder.set_align_text("a")
    step = CMN_SECONDS * RATE * 2
    if len(pcm) <= step:
        decode(decoder, pcm)
        return decoder.get_cmn()
    total = np.zeros(0)
    for s in range(0, len(pcm), step):
        decode(decoder, pcm[s:s + step])
        mean = np.array([float(v) for v in decoder.get_cmn().split(",")]) * len(pcm[s:s + step])
        total = mean if not len(total) else total + mean
    return ",".join(f"{v:g}" for v in total / len(pcm))


def unknown_share(transcript: str) -> float:
    """The share of the transcript's words pocketsphinx's English dictionary lacks (the recogniser's: the
    aligners' dictionaries gain the words they are given)."""
    tokens = [t for _, said in normalize_transcript(transcript) for t in said]
    with LOCK:
        return sum(get_decoder("recognize").lookup_word(t) is None for t in tokens) / max(len(tokens), 1)
