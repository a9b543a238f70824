"""Phonetics, one table each: the phone set, espeak-ng phonemes → CMU phones, Flite/Festival phones → CMU, CMU
phones → visemes, stress, vowels and silence labels; and the phone stream built on them.

Every other module reads these tables from here: the libespeak-ng binding (facegen.espeak: `pronounce`, the
aligner's pronunciations of words pocketsphinx does not know), the aligner (fillers, SIL), alignment files
(pause labels), the lip-sync metrics, the synthetic rig's curves (facegen.synth.curves: visemes, stress,
vowels) and the synthesisers' phones (facegen.synth.voices). It imports nothing of facegen but errors.

* The phone set is pocketsphinx's en-us set (CMU/ARPAbet without stress digits): 15 vowels, 24 consonants.
* espeak → CMU (`ESPEAK_TO_CMU`, `espeak_to_cmu`): the one table, the aligner's since before issue 21. Until
  then the synthetic curves kept a second table, espeak phonemes → visemes, that disagreed with it on 14 of
  the phonemes espeak-ng en-us speaks ("a" → AA, "V" → AA, "3" → R, "oU" → OW UW, ...; "y" → IH where this has
  UW). benchmarks/espeak_table.py measured which is right: the 1,228 words of the project's text (lexicon,
  sentences, example) that pocketsphinx's cmudict-en-us.dict knows, phonemized by espeak-ng en-us (6,356
  phonemes), each table's visemes aligned to the dictionary's. Agreement per phoneme, this table vs the old
  curves table: "a" (n=116) 98 % vs 0 %, "V" (130) 98 vs 2, "3" (143) 97 vs 3, "oU" (104) 100 vs 0, "a#" (51)
  92 vs 0, "aa" (34) 100 vs 0, "o@" (30) 97 vs 0, "e@" (21) 100 vs 0, "O@" (17) 94 vs 0, "U@" (11) 91 vs 0,
  "A@" (37) 100 vs 100; the old table only wins "@L" (86; 98 vs 100 %) and "aI@" (2; 0 vs 100 %). All
  phonemes: 96.4 % vs 86.9 %; the 802 disputed ones 95.0 % vs 16.6 %; viseme edit distance 3.1 vs 14.7 per 100
  visemes; words right throughout 84.1 % vs 47.2 %. Every other English voice of the corpora (en, en-gb-x-rp,
  en-gb-scotland, en-us-nyc, en-029) gives the same verdict. No English voice says "y" or "Y" on these words:
  they keep UW (espeak's y is the rounded [y], whose lips are UW's). Known weak spot, kept for the aligner's
  sake: "i@3" → IY R agrees 5 % (the dictionary says IH R).
* CMU → visemes (`CMU_VISEMES`): the rig's mouth shapes, named after the CMU vowels they look like (diphthongs
  as two). An espeak phoneme's visemes are those of its CMU phones (`phone_visemes`).
* The phone stream (`PHONES`, `phone_frames`): per-frame phone identity (one-hot over SIL + the CMU phones),
  an extra input of the audio encoder for models trained with it (facegen.model: `n_phones`). At inference the
  phones come from pocketsphinx's phone alignment of the transcript (facegen.align.align_phones) or from an
  alignment file that lists them; in training from the corpus's phone timings (the synthesiser's own, espeak
  mnemonics or CMU phones, mapped to CMU here).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from facegen.errors import FacegenError

# ------------------------------------------------------------------------------------------- phone set
# pocketsphinx's en-us phone set, what espeak_to_cmu maps to
CMU_VOWELS = ("AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW", "OY", "UH", "UW")
CMU_CONSONANTS = ("B", "CH", "D", "DH", "F", "G", "HH", "JH", "K", "L", "M", "N", "NG", "P", "R", "S", "SH",
                  "T", "TH", "V", "W", "Y", "Z", "ZH")
SIL = "SIL"  # pocketsphinx's silence phone; class 0 of the phone stream
PHONES = (SIL, *CMU_VOWELS, *CMU_CONSONANTS)
INDEX = {p: i for i, p in enumerate(PHONES)}
ALPHABETS = ("espeak", "cmu")  # the phone names facegen reads: espeak-ng mnemonics or CMU phones

# ---------------------------------------------------------------------------------------------- silence
ESPEAK_PAUSE = "_"  # espeak's pauses start with it: "_", "_:", "_!"
FILLER_MARKS = ("<", "[", "+")  # pocketsphinx's fillers: <s> </s> <sil> [NOISE] +SPN+
# pause labels of alignment files and synthesisers (lower case): TextGrid/MFA, Kaldi, Flite/Festival, TIMIT
PAUSE_LABELS = frozenset({"", "sil", "sp", "<eps>", "<sil>", "{sl}", "#", "pau", "h#", "ssil"})


def is_filler(word: str) -> bool:
    """Whether a word of pocketsphinx's search is one of its fillers (silence or noise), not a word."""
    return word.startswith(FILLER_MARKS)


def is_pause(label: str) -> bool:
    """Whether a label of an alignment file or a synthesiser's phone is a pause (PAUSE_LABELS)."""
    return label.lower() in PAUSE_LABELS


def is_silence(name: str) -> bool:
    """Whether a word or phone name of any source is silence rather than speech: a pause label, SIL, an espeak
    pause (_...) or a pocketsphinx filler."""
    return is_pause(name) or name.upper() == SIL or name.startswith((ESPEAK_PAUSE, *FILLER_MARKS))


# --------------------------------------------------------------------------------------------- stress
STRESS_MARKS = "'`,%=\"!"  # espeak's stress and emphasis marks, stripped before a mnemonic is looked up
_NO_STRESS = str.maketrans("", "", STRESS_MARKS)


def phone_stress(mnemonic: str, alphabet: str = "espeak") -> float | None:
    """1.0 for a phone marked with primary stress, 0.5 secondary, 0.0 unstressed, None when unmarked
    (espeak: a leading ' or , ; CMU: the digit 1, 2 or 0)."""
    name = mnemonic.strip()
    if alphabet == "cmu":
        return {"1": 1.0, "2": 0.5, "0": 0.0}.get(name[-1:]) if name else None
    if name.startswith("'"):
        return 1.0
    return 0.5 if name.startswith(",") else None


# ------------------------------------------------------------------------------------- espeak → CMU
ESPEAK_TO_CMU = {
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
_LONGEST = max(len(k) for k in ESPEAK_TO_CMU)


def espeak_to_cmu(phonemes: Sequence[str]) -> list[str]:
    """Map espeak phoneme mnemonics to pocketsphinx (CMU) phones; unknown symbols are skipped."""
    out: list[str] = []
    for ph in phonemes:
        ph = ph.translate(_NO_STRESS)
        i = 0
        while i < len(ph):  # longest match, so "aI@" or unusual compounds still map
            for size in range(min(_LONGEST, len(ph) - i), 0, -1):
                cmu = ESPEAK_TO_CMU.get(ph[i:i + size])
                if cmu:
                    for p in cmu.split():
                        if not out or out[-1] != p or p not in CMU_CONSONANTS:  # "bb" → B
                            out.append(p)
                    i += size
                    break
            else:
                i += 1
    return out


# ----------------------------------------------------------------------------------------- IPA → CMU
# Any language espeak-ng reads gives its phones in the IPA (facegen.espeak.phonemize(ipa=True)). A phone with
# a CMU counterpart maps to it (CMU_IPA, IPA_ALIASES); any other goes to the CMU phone nearest in the
# articulatory features of panphon (a well-kept IPA feature table), weighted by what shows on the lips and jaw
# (VISIBLE_WEIGHTS: labial, round, high, low, back, syllabic ...): French /y/ rounds (UW), a Spanish /β/
# between vowels ([β]) a labial that does not close as /b/ does (V), /ʁ/ is made at the back (HH), not a
# rounded English R. A tapped or trilled /r/ (Italian, Spanish, Russian ...) is the English flap, which the
# aligner's model knows as D (its nearest in features, L, fit the sounds worse: on 13 Italian, Spanish,
# Russian and Czech lines the median word's score gap fell 9.5 -> 5.9 and the largest 21.3 -> 16.1).
CMU_IPA = {"AA": "ɑ", "AE": "æ", "AH": "ʌ", "AO": "ɔ", "AW": "aʊ", "AY": "aɪ", "EH": "ɛ", "ER": "ɝ",
           "EY": "eɪ", "IH": "ɪ", "IY": "i", "OW": "oʊ", "OY": "ɔɪ", "UH": "ʊ", "UW": "u",
           "B": "b", "CH": "tʃ", "D": "d", "DH": "ð", "F": "f", "G": "ɡ", "HH": "h", "JH": "dʒ", "K": "k",
           "L": "l", "M": "m", "N": "n", "NG": "ŋ", "P": "p", "R": "ɹ", "S": "s", "SH": "ʃ", "T": "t",
           "TH": "θ", "V": "v", "W": "w", "Y": "j", "Z": "z", "ZH": "ʒ"}
IPA_ALIASES = {"ə": "AH", "ɐ": "AH", "ɜ": "ER", "ɚ": "ER", "a": "AA", "e": "EY", "o": "OW", "g": "G",
               "ɾ": "D", "r": "D", "ɫ": "L", "ʧ": "CH", "ʤ": "JH", "ts": "T S", "dz": "D Z", "ɹ̩": "ER",
               "ʍ": "W", "β": "V", "ɸ": "F", "ʋ": "V", "ø": "OW"}  # lips that near but do not close: not B, P
VISIBLE_WEIGHTS = {"syl": 3.0, "cons": 2.0, "lab": 3.0, "round": 3.0, "lo": 2.0, "hi": 2.0, "back": 1.5,
                   "cor": 1.5, "ant": 1.0, "son": 1.0, "cont": 1.0, "lat": 1.0, "strid": 1.0, "distr": 0.5,
                   "nas": 0.5, "delrel": 0.5}
_IPA_MARKS = str.maketrans("", "", "ˈˌːˑ‿̯͡")
_IPA_CACHE: dict[str, tuple[str, ...]] = {}


def ipa_to_cmu(phones: Sequence[str]) -> list[str]:
    """Map IPA phones (one string each, stress and length marks allowed) to pocketsphinx (CMU) phones; what
    panphon cannot read is skipped."""
    out: list[str] = []
    for ph in phones:
        key = ph.translate(_IPA_MARKS)
        if key not in _IPA_CACHE:
            _IPA_CACHE[key] = _nearest_cmu(key)
        for p in _IPA_CACHE[key]:
            if not out or out[-1] != p or p not in CMU_CONSONANTS:
                out.append(p)
    return out


def _nearest_cmu(ipa: str) -> tuple[str, ...]:
    direct = {v: k for k, v in CMU_IPA.items()} | IPA_ALIASES
    if ipa in direct:
        return tuple(direct[ipa].split())
    table = _feature_table()
    if table is None:
        return ()
    ft, weights, singles = table
    found = []
    for segment in ft.ipa_segs(ipa):
        vectors = ft.word_to_vector_list(segment, numeric=True)
        if not vectors:
            continue
        v = np.asarray(vectors[0], np.float64)
        if segment in direct:
            found += direct[segment].split()
            continue
        cost = {p: float(np.sum(weights * np.abs(v - u))) for p, u in singles.items()}
        found.append(min(cost, key=cost.get))
    return tuple(found)


_TABLE: list = []


def _feature_table():
    """(panphon FeatureTable, feature weights, {CMU phone: feature vector} of the one-segment CMU phones),
    built once; None without panphon."""
    if not _TABLE:
        try:
            import panphon
        except ImportError:
            _TABLE.append(None)
            return None
        ft = panphon.FeatureTable()
        weights = np.array([VISIBLE_WEIGHTS.get(n, 0.2) for n in ft.names])
        singles = {p: np.asarray(ft.word_to_vector_list(ipa, numeric=True)[0], np.float64)
                   for p, ipa in CMU_IPA.items() if len(ft.ipa_segs(ipa)) == 1}
        _TABLE.append((ft, weights, singles))
    return _TABLE[0]


# ------------------------------------------------------------------------- Flite/Festival phones → CMU
# The radio phone set of Flite's and Festival's US voices -> CMU without stress (their pauses: is_pause).
RADIO_TO_CMU = {p: p.upper() for p in (
    "aa", "ae", "ah", "ao", "aw", "ay", "b", "ch", "d", "dh", "eh", "er", "ey", "f", "g", "hh", "ih", "iy",
    "jh", "k", "l", "m", "n", "ng", "ow", "oy", "p", "r", "s", "sh", "t", "th", "uh", "uw", "v", "w", "y",
    "z", "zh",
)} | {"ax": "AH", "axr": "ER"}


# -------------------------------------------------------------------------------------------- visemes
# CMU phones (stress digits dropped) -> the rig's visemes (facegen.synth.curves.VISEMES); DX is a flap
CMU_VISEMES: dict[str, tuple[str, ...]] = {
    **{p: ("PBM",) for p in ("P", "B", "M")}, **{p: ("FV",) for p in ("F", "V")},
    **{p: ("TH",) for p in ("TH", "DH")}, **{p: ("SZ",) for p in ("S", "Z")},
    **{p: ("SH",) for p in ("SH", "ZH", "CH", "JH")}, **{p: ("TDN",) for p in ("T", "D", "N", "DX")},
    "L": ("L",), "R": ("R",), **{p: ("KG",) for p in ("K", "G", "NG")}, "HH": ("H",), "W": ("W",),
    "Y": ("Y",), **{p: (p,) for p in ("AA", "AE", "AH", "ER", "EH", "IY", "IH", "AO", "OW", "UH", "UW")},
    "AW": ("AA", "UH"), "AY": ("AA", "IH"), "EY": ("EH", "IH"), "OY": ("AO", "IH"),
}
REST = "rest"  # the viseme of silence and of phones no table knows
VOWEL_VISEMES = frozenset(v for p in CMU_VOWELS for v in CMU_VISEMES[p])  # the visemes of the vowels


def phone_visemes(mnemonic: str, alphabet: str = "espeak") -> tuple[str, ...]:
    """The viseme sequence of one phone: an espeak phoneme mnemonic (the visemes of its CMU phones), or a CMU
    phone (`alphabet="cmu"`, stress digits allowed: "AH1"); silence and unknown phones are neutral (REST)."""
    if alphabet == "cmu":
        return CMU_VISEMES.get(mnemonic.strip().upper().rstrip("012"), (REST,))
    name = mnemonic.translate(_NO_STRESS).strip()
    if not name or name.startswith(ESPEAK_PAUSE):
        return (REST,)
    return tuple(v for p in espeak_to_cmu([name]) for v in CMU_VISEMES[p]) or (REST,)


def check_alphabet(alphabet: str) -> None:
    """Refuse a phone alphabet facegen does not read (ALPHABETS)."""
    if alphabet not in ALPHABETS:
        raise FacegenError(f"unknown phone alphabet {alphabet!r}: use one of {', '.join(ALPHABETS)}")


# ------------------------------------------------------------------------------------- phone stream
def to_cmu(phones: Sequence, alphabet: str = "cmu") -> list[tuple[str, float, float]]:
    """(CMU phone, start, end) from phones as (name, start, end) tuples or objects with .text/.start/.end;
    espeak mnemonics (`alphabet="espeak"`) that map to several CMU phones share their span evenly."""
    if alphabet not in ALPHABETS:
        raise FacegenError(f"unknown phone alphabet {alphabet!r}: use cmu or espeak")
    out = []
    for ph in phones:
        name, start, end = (ph.text, ph.start, ph.end) if hasattr(ph, "text") else ph[:3]
        parts = espeak_to_cmu([str(name)]) if alphabet == "espeak" else [str(name).upper().rstrip("012")]
        parts = [p for p in parts if p in INDEX]
        step = (float(end) - float(start)) / max(1, len(parts))
        out += [(p, float(start) + k * step, float(start) + (k + 1) * step) for k, p in enumerate(parts)]
    return out


def phone_frames(phones: Sequence, num_frames: int, fps: float, alphabet: str = "cmu") -> np.ndarray:
    """One-hot [num_frames, len(PHONES)] float32: the phone sounding at each frame's time k / fps (SIL where
    none is)."""
    ids = np.zeros(num_frames, np.int64)
    t = np.arange(num_frames) / fps
    for name, start, end in to_cmu(phones, alphabet):
        ids[(t >= start) & (t < end)] = INDEX[name]
    out = np.zeros((num_frames, len(PHONES)), np.float32)
    out[np.arange(num_frames), ids] = 1.0
    return out


def silence(num_frames: int) -> np.ndarray:
    """Phone frames [num_frames, len(PHONES)] of silence only (class 0)."""
    out = np.zeros((num_frames, len(PHONES)), np.float32)
    out[:, 0] = 1.0
    return out
