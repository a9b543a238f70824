"""The languages facegen reads (issue 25): every language libespeak-ng speaks, by its code ("fr", "de", "es",
"pt-BR", "cmn", ...), with its family (the ISO 639-5 group of espeak-ng's voice folders: roa Romance, gmw West
Germanic, zle East Slavic, ...) and the scripts its text is written in.

Every language is aligned by pocketsphinx's English acoustic model (facegen.align): English with its
dictionary, any other language with each word's pronunciation from espeak-ng in that language, in the IPA,
mapped to the model's phones by articulatory features (facegen.phonetics.ipa_to_cmu). `facegen languages`
lists them, with what was measured of each (benchmarks/bench_languages.py, stored in
facegen/language_figures.json: nothing is claimed that was not measured).
"""

from __future__ import annotations

import json
import os
import unicodedata
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from facegen.errors import FacegenError

DEFAULT = "en"
# held out of training and of every bound chosen on measurements (the cross-language test): three families
HELD_OUT = ("nl", "pl", "tr")
FIGURES = Path(__file__).with_name("language_figures.json")

FAMILIES = {
    "gmw": "West Germanic", "gmq": "North Germanic", "roa": "Romance", "itc": "Italic", "zle": "East Slavic",
    "zls": "South Slavic", "zlw": "West Slavic", "bat": "Baltic", "cel": "Celtic", "grk": "Greek",
    "inc": "Indo-Aryan", "ira": "Iranian", "ine": "Indo-European (other)", "urj": "Uralic", "trk": "Turkic",
    "sem": "Semitic", "sit": "Sino-Tibetan", "jpx": "Japonic", "dra": "Dravidian", "poz": "Malayo-Polynesian",
    "aav": "Austroasiatic", "tai": "Tai", "bnt": "Bantu", "cus": "Cushitic", "art": "constructed",
    "ccs": "Kartvelian", "map": "Austronesian", "iro": "Iroquoian", "azc": "Uto-Aztecan",
    "esx": "Eskimo-Aleut", "myn": "Mayan", "sai": "South American", "miz": "Mixtec"}

# the scripts (first word of a letter's Unicode name) a language's text is written in, where not Latin
SCRIPTS = {
    **dict.fromkeys(("ru", "ru-LV", "ru-cl", "uk", "be", "bg", "mk", "kk", "ky", "ba", "cv", "tt", "nog"),
                    ("CYRILLIC",)),
    "sr": ("CYRILLIC", "LATIN"), **dict.fromkeys(("el", "grc"), ("GREEK",)),
    **dict.fromkeys(("ar", "fa", "ur", "sd", "ug"), ("ARABIC",)), "he": ("HEBREW",),
    **dict.fromkeys(("hi", "mr", "ne", "kok"), ("DEVANAGARI",)),
    **dict.fromkeys(("bn", "as", "bpy"), ("BENGALI",)),
    "gu": ("GUJARATI",), "pa": ("GURMUKHI",), "or": ("ORIYA",), "ta": ("TAMIL",), "te": ("TELUGU",),
    "kn": ("KANNADA",), "ml": ("MALAYALAM",), "si": ("SINHALA",), "th": ("THAI",), "my": ("MYANMAR",),
    "shn": ("MYANMAR",), "ka": ("GEORGIAN",), "hy": ("ARMENIAN",), "hyw": ("ARMENIAN",),
    "am": ("ETHIOPIC",), "ti": ("ETHIOPIC",), "ja": ("CJK", "HIRAGANA", "KATAKANA"),
    **dict.fromkeys(("cmn", "yue", "hak"), ("CJK",)), "ko": ("HANGUL",), "chr": ("CHEROKEE",),
}
# what was found wrong in espeak-ng's reading of a language (its figures measure espeak-ng's own speech, so
# they cannot show it); `facegen languages` prints it beside them
CAVEATS = {
    "th": "espeak-ng misreads Thai (vowels written before their consonant are said first and several vowel "
          "signs as /s/: ดี → d s, แมว → a e m a w): the aligner hears Thai speech through that reading",
}
COMMON = ("ru", "uk", "bg", "sr", "el", "ar", "fa", "he", "hi", "bn", "ja", "cmn", "ko", "th")  # named first
MIN_IN_SCRIPT = 0.5  # of a transcript's letters, in its language's scripts (Latin names in any language)


@dataclass(frozen=True)
class Language:
    code: str  # espeak-ng's voice name, what --language takes
    family: str  # ISO 639-5 code (FAMILIES)
    scripts: tuple[str, ...]

    @property
    def voice(self) -> str:
        return "en-us" if self.code == DEFAULT else self.code

    @property
    def family_name(self) -> str:
        return FAMILIES.get(self.family, self.family)


@cache
def languages() -> dict[str, Language]:
    """Every language espeak-ng has a voice for, by code (lower case keys)."""
    import espeakng_loader

    root = Path(espeakng_loader.get_data_path()) / "lang"
    out = {DEFAULT: Language(DEFAULT, "gmw", ("LATIN",))}
    for folder, _, files in os.walk(root):
        family = Path(folder).relative_to(root).parts[0] if Path(folder) != root else ""
        for code in files:
            if code.lower() not in out and code.lower() not in ("en-us",):
                out[code.lower()] = Language(code, family, SCRIPTS.get(code, ("LATIN",)))
    return dict(sorted(out.items()))


# locale tags pipelines write (BCP 47) that name no espeak-ng voice, and the voice that reads them; any other
# unknown tag with a region ("fr-CA", "de-AT", "pt-PT") reads as its language ("fr", "de", "pt")
ALIASES = {"en-us": DEFAULT, "en-gb": "en-gb-x-rp", "en-uk": "en-gb-x-rp",
           **dict.fromkeys(("zh", "zh-cn", "zh-hans", "zh-sg", "zh-tw", "zh-hant"), "cmn"), "zh-hk": "yue",
           **{f"es-{region}": "es-419" for region in (
               "mx", "us", "ar", "bo", "cl", "co", "cr", "cu", "do", "ec", "gt", "hn", "ni", "pa", "pe", "pr",
               "py", "sv", "uy", "ve")}}


def check_language(code: str | None) -> Language:
    """The Language of `code` (None: English): an espeak-ng voice name, or a locale tag (ALIASES, or a
    language with a region espeak-ng has no voice for: its language's). An unknown code is a FacegenError
    saying how to list them."""
    if code is None:
        code = DEFAULT
    key = str(code).strip().lower().replace("_", "-")
    found = None
    if isinstance(code, str):
        table = languages()
        key = ALIASES.get(key, key)
        found = table.get(key) or (table.get(key.split("-")[0]) if "-" in key else None)
    if found is None:
        raise FacegenError(f"unknown language {code!r}: `facegen languages` lists the codes (e.g. en, fr, "
                           "de, es, pt-BR, ru, cmn)", param="language")
    return found


def script_of(char: str) -> str:
    name = unicodedata.name(char, "")
    return name.split()[0] if name else ""


def check_script(text: str, language: Language) -> None:
    """Refuse a transcript whose letters are mostly in a script the language is not written in (e.g. Cyrillic
    text with --language fr), naming the languages that script may be."""
    letters = [c for c in text if c.isalpha()]
    if not letters:
        return
    allowed = set(language.scripts) | {"LATIN"}
    inside = sum(script_of(c) in allowed for c in letters) / len(letters)
    if inside >= MIN_IN_SCRIPT:
        return
    counts: dict[str, int] = {}
    for c in letters:
        counts[script_of(c)] = counts.get(script_of(c), 0) + 1
    script = max(counts, key=counts.get)
    maybe = sorted((lang.code for lang in languages().values() if script in lang.scripts),
                   key=lambda c: (COMMON.index(c) if c in COMMON else len(COMMON), c))[:4]
    hint = f" (e.g. --language {' or '.join(maybe)})" if maybe else ""
    raise FacegenError(f"the transcript is written in {script.title()} script, which {language.code} is not "
                       f"written in: pass its language{hint}", param="language")


def figures() -> dict[str, dict]:
    """What benchmarks/bench_languages.py measured per language code ({} where nothing was)."""
    if not FIGURES.exists():
        return {}
    return json.loads(FIGURES.read_text())
