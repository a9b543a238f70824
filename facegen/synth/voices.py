"""Speech synthesisers behind one voice registry: libespeak-ng (in-process, facegen.espeak), Flite and
Festival (Debian packages) voices with stable names ("espeak:en-us+f3", "flite:slt", "festival:kal_diphone"),
each synthesised to an `Utterance` with the engine's own phone and word timings (CMU phones; espeak's own
mnemonics for English espeak voices, which the rig reads natively; other languages' phones labelled from
espeak-ng's IPA as CMU phones — `Utterance.alphabet` says which).

An engine is one `Engine` subclass (its binary, the Debian packages that install it, its voices and one
`_synthesize`); adding one (e.g. espeak-ng variants) is one class plus one entry in `ENGINES`. Every engine
runs as a subprocess in a temporary folder, with a timeout and its stderr captured for the error message.
"""

from __future__ import annotations

import functools
import re
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from facegen.audio import load_audio
from facegen.errors import FacegenError
from facegen.phonetics import RADIO_TO_CMU, is_pause
from facegen.processes import run_tool, tool_path

Timing = tuple[str, float, float]
# the languages the voices corpus speaks besides English (facegen.synth.voice_corpus): 20 languages of 9
# families with word lists in wordfreq (facegen.synth.foreign_sentences); never facegen.languages.HELD_OUT
CORPUS_LANGUAGES = ("fr", "es", "pt", "it", "ro", "ca", "de", "sv", "da", "nb", "ru", "uk", "cs", "bg", "el",
                    "fi", "hu", "id", "hi", "vi")
# their voice variants: (gender, pitch 0-100, words per minute)
FOREIGN_VARIANTS = {"m1": ("male", 45, 160), "f2": ("female", 55, 150), "m3": ("male", 50, 165),
                    "f3": ("female", 60, 155), "m4": ("male", 40, 150), "f4": ("female", 50, 160)}


@dataclass(frozen=True)
class Voice:
    """One voice: `name` is "engine:id", `package` the Debian package that installs it."""

    engine: str
    id: str
    gender: str
    package: str
    description: str

    @property
    def name(self) -> str:
        return f"{self.engine}:{self.id}"


@dataclass
class Utterance:
    """Synthesised speech: mono float32 audio at the engine's own rate, and the engine's phone timings (CMU
    phones, silences left out) and word timings in seconds, or None where the engine gives none."""

    audio: np.ndarray
    sample_rate: int
    phones: list[Timing] | None
    words: list[Timing] | None
    voice: str
    alphabet: str = "cmu"  # of the phones: "cmu", or "espeak" (espeak-ng mnemonics, stress marks kept)

    @property
    def duration(self) -> float:
        return len(self.audio) / self.sample_rate


def cmu_phone(phone: str, voice: str) -> str | None:
    """A radio-set phone as a CMU phone (upper case, no stress); None for a silence."""
    if is_pause(phone):
        return None
    if phone not in RADIO_TO_CMU:
        raise FacegenError(f"voice {voice} produced the phone {phone!r}, which is not in the CMU set: "
                           "use an English voice")
    return RADIO_TO_CMU[phone]


def _timings(segments: list[tuple[str, float]], voice: str) -> list[Timing]:
    """(radio phone, end time) segments -> CMU (phone, start, end), silences dropped."""
    out, start = [], 0.0
    for phone, end in segments:
        cmu = cmu_phone(phone, voice)
        if cmu is not None:
            out.append((cmu, start, end))
        start = end
    return out


class Engine:
    """One synthesiser: subclasses set the class attributes, `installed_ids` and `_synthesize` (a subprocess
    engine), or `installed_ids` and `synthesize` (an in-process library such as libespeak-ng)."""

    name: str
    binary: str
    install: str  # the apt-get line that installs the engine
    voices: tuple[Voice, ...]

    def executable(self) -> str:
        """The engine's binary, or a FacegenError naming the Debian packages to install."""
        return tool_path(self.binary, f"run `{self.install}` as root, or `make voices`")

    def is_installed(self) -> bool:
        """Whether the engine's binary is on PATH."""
        try:
            return bool(self.executable())
        except FacegenError:
            return False

    def installed_ids(self) -> set[str]:
        """The ids of this engine's voices installed now (empty when the engine itself is not)."""
        raise NotImplementedError

    def synthesize(self, text: str, voice: Voice, rate: float) -> Utterance:
        """`text` said by `voice` at `rate` (checked by the module's `synthesize`)."""
        self.executable()
        with tempfile.TemporaryDirectory(prefix=f"facegen-{self.name}-") as tmp:
            return self._synthesize(self.binary, text, voice, rate, Path(tmp))

    def _synthesize(self, exe: str, text: str, voice: Voice, rate: float, tmp: Path) -> Utterance:
        """`exe`: the binary's name, for _run."""
        raise NotImplementedError

    def _not_installed(self, voice: Voice) -> FacegenError:
        return FacegenError(f"voice {voice.name} is not installed: run `apt-get install {voice.package}` "
                            "as root, or `make voices`")


def _run(cmd: list[str], what: str, timeout: float, cwd: Path | None = None) -> str:
    """Run a synthesiser (cmd[0]: its binary's name, processes.run_tool); its stdout, or a FacegenError
    carrying the last line of its stderr."""
    try:
        proc = run_tool(cmd[0], cmd[1:], text=True, timeout=timeout, cwd=cwd)
    except subprocess.TimeoutExpired as exc:
        raise FacegenError(f"{what} did not finish within {timeout:.0f} s: try a shorter text") from exc
    if proc.returncode != 0:
        lines = [ln.strip() for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip()]
        detail = next((ln for ln in lines if "ERROR" in ln), lines[-1] if lines else "no message")
        raise FacegenError(f"{what} failed (exit {proc.returncode}: {detail})")
    return proc.stdout


def _timeout(text: str) -> float:
    return 30.0 + 0.2 * len(text)


def _read_wav(path: Path, voice: Voice, text: str) -> tuple[np.ndarray, int]:
    if not path.exists() or path.stat().st_size <= 44:
        raise FacegenError(f"voice {voice.name} produced no audio for {text[:60]!r}: give it words to say")
    return load_audio(path, what=f"{voice.name} output")


class Flite(Engine):
    """CMU Flite's built-in voices. `-psdur` prints each segment's end time; word boundaries come from the
    words Flite says (`-pw`) and each word's phone count (the words said one by one, `-ps`). (libflite through
    ctypes would give both in one call, but in-process and unguarded; three short runs cost ~0.3 s.)"""

    name, binary, install = "flite", "flite", "apt-get install flite"
    voices = (
        Voice("flite", "slt", "female", "flite", "US English female (CMU ARCTIC slt), clustergen"),
        Voice("flite", "rms", "male", "flite", "US English male (CMU ARCTIC rms), clustergen"),
        Voice("flite", "awb", "male", "flite", "Scottish English male (CMU ARCTIC awb), clustergen"),
        Voice("flite", "kal16", "male", "flite", "US English male (kal), diphone, 16 kHz"),
        Voice("flite", "kal", "male", "flite", "US English male (kal), diphone, 8 kHz"),
    )

    def installed_ids(self) -> set[str]:
        return _flite_voice_list(self.binary) if self.is_installed() else set()

    def _synthesize(self, exe: str, text: str, voice: Voice, rate: float, tmp: Path) -> Utterance:
        if voice.id not in _flite_voice_list(exe):
            raise self._not_installed(voice)
        what, timeout = f"flite voice {voice.id}", _timeout(text)
        stretch = _FLITE_STRETCH.get(voice.id, 1.0) / rate
        base = [exe, "-voice", voice.id, "--setf", f"duration_stretch={stretch:.6f}"]
        wav = tmp / "out.wav"
        out = _run([*base, "-psdur", "-t", text, "-o", str(wav)], what, timeout)
        segments = [(p, float(t)) for p, t in re.findall(r"(\S+):([0-9.]+)", out)]
        audio, sr = _read_wav(wav, voice, text)
        phones = _timings(segments, voice.name)
        # words and their phone counts through the fast diphone voice (the same tokenizer, lexicon and
        # post-lexical rules); a count that does not add up leaves the words to forced alignment
        lexical = [exe, "-voice", "kal16" if "kal16" in _flite_voice_list(exe) else voice.id]
        said: list[str] = []
        for w in _run([*lexical, "-pw", "-t", text, "none"], what, timeout).split():
            # a clitic ('s, 'll) said alone is spelled out: keep it on its word
            if w.startswith("'") and said:
                said[-1] += w
            else:
                said.append(w)
        words = None
        if said:
            one_by_one = _run([*lexical, "-ps", "-t", " ".join(f"{w}." for w in said), "none"], what, timeout)
            counts = [len(g.split()) for g in re.split(r"\bpau\b", one_by_one) if g.strip()]
            words = _word_spans(said, counts, phones)
        return Utterance(audio, sr, phones, words, voice.name)


# Voices whose built-in duration_stretch is not 1 (flite's kal voices say everything 10 % slower).
_FLITE_STRETCH = {"kal": 1.1, "kal16": 1.1}


@functools.lru_cache(maxsize=8)
def _flite_voice_list(exe: str) -> set[str]:
    out = _run([exe, "-lv"], "flite -lv", 30.0)
    return set(out.split(":", 1)[-1].split())


def _word_spans(words: list[str], counts: list[int], phones: list[Timing]) -> list[Timing] | None:
    """Words over consecutive phones, given each word's phone count; None when the counts do not add up."""
    if len(counts) != len(words) or sum(counts) != len(phones) or min(counts, default=0) < 1:
        return None
    spans, k = [], 0
    for word, n in zip(words, counts, strict=True):
        spans.append((word, phones[k][1], phones[k + n - 1][2]))
        k += n
    return spans


class Festival(Engine):
    """The Festival Speech Synthesis System, driven by a Scheme script: its Segment and Word relations give
    the phone and word times the waveform was built from (diphone voices stretch with Duration_Stretch, HTS
    voices with hts_engine's speed rate `-r`)."""

    name, binary = "festival", "festival"
    install = "apt-get install festival festvox-kallpc16k festvox-kdlpc16k festvox-us-slt-hts"
    voices = (
        Voice("festival", "kal_diphone", "male", "festvox-kallpc16k", "US English male (kal), LPC diphone"),
        Voice("festival", "ked_diphone", "male", "festvox-kdlpc16k", "US English male (ked), LPC diphone"),
        Voice("festival", "cmu_us_slt_arctic_hts", "female", "festvox-us-slt-hts",
              "US English female (CMU ARCTIC slt), HTS statistical parametric, 32 kHz"),
    )

    def installed_ids(self) -> set[str]:
        return _festival_voice_list(self.binary) if self.is_installed() else set()

    def _synthesize(self, exe: str, text: str, voice: Voice, rate: float, tmp: Path) -> Utterance:
        wav, script = tmp / "out.wav", tmp / "say.scm"
        said = " ".join(text.split()).replace("\\", "\\\\").replace('"', '\\"')
        if voice.id.endswith("_hts"):
            speed = f'(set! hts_engine_params (append hts_engine_params (list (list "-r" {rate:.6f}))))'
        else:
            speed = f"(Parameter.set 'Duration_Stretch (/ (Parameter.get 'Duration_Stretch) {rate:.6f}))"
        script.write_text(
            f"(voice_{voice.id})\n{speed}\n"
            f'(set! utt (SynthText "{said}"))\n'
            f"(utt.save.wave utt \"{wav}\" 'riff)\n"
            "(mapcar (lambda (s) (format t \"SEG\\t%s\\t%f\\n\" (item.name s) (item.feat s 'end)))"
            " (utt.relation.items utt 'Segment))\n"
            "(mapcar (lambda (w) (format t \"WORD\\t%s\\t%f\\t%f\\n\" (item.name w) (item.feat w 'word_start)"
            " (item.feat w 'word_end))) (utt.relation.items utt 'Word))\n"
        )
        try:
            out = _run([exe, "-b", str(script)], f"festival voice {voice.id}", _timeout(text), cwd=tmp)
        except FacegenError as exc:
            if f"unbound variable : voice_{voice.id}" in str(exc):
                raise self._not_installed(voice) from None
            raise
        audio, sr = _read_wav(wav, voice, text)
        rows = [line.split("\t") for line in out.splitlines()]
        phones = _timings([(r[1], float(r[2])) for r in rows if r[0] == "SEG" and len(r) == 3], voice.name)
        words = [(r[1], float(r[2]), float(r[3])) for r in rows if r[0] == "WORD" and len(r) == 4]
        return Utterance(audio, sr, phones, words, voice.name)


def _festival_voice_list(exe: str) -> set[str]:
    with tempfile.TemporaryDirectory(prefix="facegen-festival-") as tmp:
        script = Path(tmp) / "list.scm"
        script.write_text("(mapcar (lambda (v) (format t \"VOICE\\t%s\\n\" v)) (voice.list))\n")
        out = _run([exe, "-b", str(script)], "festival voice.list", 60.0)
    return {line.split("\t")[1] for line in out.splitlines() if line.startswith("VOICE\t")}


class Espeak(Engine):
    """libespeak-ng in-process (facegen.espeak): English languages x voice variants, each with its own pitch
    and speaking rate, so the voices differ in timbre, accent, pitch and tempo; and the other languages of
    the voices corpus (facegen.synth.voice_corpus.LANGUAGES) x FOREIGN_VARIANTS ("espeak:fr+m3")."""

    name, binary, install = "espeak", "", "pip install espeakng-loader"
    # (language+variant, gender, pitch 0-100, words per minute)
    _SETTINGS: ClassVar[dict[str, tuple[str, int, int]]] = {
        "en-us+f1": ("female", 55, 160), "en+f2": ("female", 50, 150), "en-us+f3": ("female", 45, 165),
        "en-gb-x-rp+f4": ("female", 60, 150), "en-029+f5": ("female", 48, 155), "en+belinda": ("female", 40,
                                                                                               165),
        "en-us+steph": ("female", 52, 145), "en-gb-scotland+linda": ("female", 58, 160),
        "en-us+m1": ("male", 45, 160), "en+m2": ("male", 55, 152), "en-us-nyc+m3": ("male", 50, 168),
        "en-gb-x-rp+m4": ("male", 40, 146), "en-us+m6": ("male", 60, 158), "en-gb-scotland+m7": ("male", 50,
                                                                                                 154),
        "en-us+klatt": ("male", 50, 160), "en+whisper": ("female", 50, 150),
        **{f"{code}+{variant}": setting for code in CORPUS_LANGUAGES
           for variant, setting in FOREIGN_VARIANTS.items()},
    }
    voices = tuple(Voice("espeak", k, g, "espeakng-loader (PyPI)", f"espeak-ng {k}, pitch {p}, {r} wpm")
                   for k, (g, p, r) in _SETTINGS.items())

    def installed_ids(self) -> set[str]:
        try:
            import espeakng_loader  # noqa: F401
        except ImportError:
            return set()
        return {v.id for v in self.voices}

    def synthesize(self, text: str, voice: Voice, rate: float) -> Utterance:
        from facegen.espeak import synthesize

        _, pitch, wpm = self._SETTINGS[voice.id]
        speech = synthesize(text, voice.id, pitch=pitch, rate=round(min(max(wpm * rate, 80), 450)))
        words = [(w.text, w.start, w.end) for w in speech.words]
        language = voice.id.split("+")[0]
        if not language.startswith("en"):  # espeak's mnemonics differ per language: CMU phones from the IPA
            return Utterance(speech.audio, speech.sample_rate, ipa_phone_times(speech, language), words,
                             voice.name, alphabet="cmu")
        phones = [(p.text, p.start, p.end) for p in speech.phones if not p.text.startswith("_")]
        return Utterance(speech.audio, speech.sample_rate, phones, words, voice.name, alphabet="espeak")


def ipa_phone_times(speech, language: str) -> list[Timing]:
    """The phones libespeak-ng spoke in `speech` (facegen.espeak.Speech) as CMU phones with their times,
    labelled from espeak-ng's IPA of each word in `language` (facegen.phonetics.ipa_to_cmu: articulatory
    features, so a French /y/ is a rounded UW). Where the synthesiser spoke as many phones as the IPA lists,
    each keeps its own time (split evenly where one IPA phone maps to several); otherwise the word's phones
    share its time, vowels twice a consonant's share."""
    from facegen.espeak import phonemize
    from facegen.phonetics import CMU_VOWELS, ipa_to_cmu, is_silence

    out: list[Timing] = []
    for k, word in enumerate(speech.words):
        ipa = phonemize(word.text, language, ipa=True)
        own = [p for p in speech.phones if p.word == k and not is_silence(p.text)]
        if own and len(own) == len(ipa):
            for segment, p in zip(ipa, own, strict=True):
                parts = ipa_to_cmu([segment])
                edges = np.linspace(p.start, p.end, len(parts) + 1)
                out += [(c, float(edges[i]), float(edges[i + 1])) for i, c in enumerate(parts)]
            continue
        cmu = ipa_to_cmu(ipa)
        if not cmu:
            continue
        weights = np.array([2.0 if c in CMU_VOWELS else 1.0 for c in cmu])
        shares = np.concatenate([[0.0], np.cumsum(weights)]) / weights.sum()
        edges = word.start + (word.end - word.start) * shares
        out += [(c, float(edges[i]), float(edges[i + 1])) for i, c in enumerate(cmu)]
    return out


ENGINES: dict[str, Engine] = {e.name: e for e in (Espeak(), Flite(), Festival())}
VOICES: dict[str, Voice] = {v.name: v for e in ENGINES.values() for v in e.voices}


def get_voice(name: str) -> Voice:
    """A voice by its registry name, or a FacegenError listing the known ones."""
    if name not in VOICES:
        raise FacegenError(f"unknown voice {name!r}: choose one of {', '.join(VOICES)}")
    return VOICES[name]


def available_voices() -> list[Voice]:
    """The registry's voices installed on this machine now."""
    return [v for e in ENGINES.values() for ids in [e.installed_ids()] for v in e.voices if v.id in ids]


def synthesize(text: str, voice: str | Voice, *, rate: float = 1.0) -> Utterance:
    """Say `text` with `voice` (a registry name or Voice); `rate` > 1 speaks faster (durations / rate)."""
    v = voice if isinstance(voice, Voice) else get_voice(voice)
    if not re.search(r"\w", text):
        raise FacegenError(f"nothing to say in {text!r}: give {v.name} a text with words")
    if not 0.25 <= rate <= 4.0:
        raise FacegenError(f"speech rate {rate} is outside 0.25-4: pass a rate near 1")
    utt = ENGINES[v.engine].synthesize(text, v, float(rate))
    if utt.phones is not None and not utt.phones:
        raise FacegenError(f"voice {v.name} said nothing for {text[:60]!r}: give it words it can pronounce")
    return utt
