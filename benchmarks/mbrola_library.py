"""A prompt library in another language said by MBROLA voices: speech from recorded diphones (real voices
cut into sound pairs), nearer recorded speech than espeak-ng's formant synthesis, and none of the recordings
kept back for issue 25's independent check (Festival's non-English voices, Asterisk's prompts). It asks
whether the foreign bound of the mismatch check (facegen.transcript_match.FOREIGN_WORD_GAP) could be chosen
on speech like it (docs/results.md, "Every language": it could not).

Writes, into OUT, NAME.wav for every line (16 kHz as MBROLA says it, or `--telephone`: 8 kHz, the band of a
phone or IVR prompt library) and script.txt in Asterisk's script format (`name: text`), so that
benchmarks/bench_mismatch.py reads it with `--sounds OUT --script OUT/script.txt`. The lines are the voices
corpus's sentences of the language (facegen.synth.foreign_sentences: its common words, 5-11 a line), said in
turn by the language's MBROLA voices through the espeak-ng program (Debian: `apt-get install espeak-ng mbrola
mbrola-fr1 mbrola-fr4 mbrola-it3 mbrola-it4 mbrola-es1 mbrola-es2 mbrola-de2 mbrola-de6 mbrola-br1`, the
voices from Debian's contrib and non-free components).

    python benchmarks/mbrola_library.py OUT --language fr [--lines 60] [--telephone]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

VOICES = {"fr": ("mb-fr1", "mb-fr4"), "it": ("mb-it3", "mb-it4"), "es": ("mb-es1", "mb-es2"),
          "de": ("mb-de2", "mb-de6"), "pt": ("mb-br1",)}


def build(out: Path, language: str, lines: int = 60, telephone: bool = False, seed: int = 7) -> list[str]:
    """Synthesise the library into `out`; the names of the lines made."""
    import librosa
    import soundfile as sf

    from facegen.synth.foreign_sentences import foreign_sentences

    if shutil.which("espeak-ng") is None:
        raise SystemExit("no espeak-ng program: apt-get install espeak-ng mbrola and the mbrola-* voices")
    voices = [v for v in VOICES[language] if Path("/usr/share/mbrola", v[3:]).is_dir()]
    if not voices:
        raise SystemExit(f"no MBROLA voice for {language}: apt-get install "
                         + " ".join(f"mbrola-{v[3:]}" for v in VOICES[language]))
    out.mkdir(parents=True, exist_ok=True)
    made, script = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for k, text in enumerate(foreign_sentences(language, lines, seed=seed)):
            voice, name = voices[k % len(voices)], f"{language}_{k:03d}"
            raw = Path(tmp) / "raw.wav"
            proc = subprocess.run(["espeak-ng", "-v", voice, "-s", "150", "-w", str(raw), text],
                                  capture_output=True, text=True, check=False)
            if proc.returncode or not raw.is_file() or raw.stat().st_size < 2000:
                print(f"  {name}: {voice} said nothing ({proc.stderr.strip()[:80]})", file=sys.stderr)
                continue
            audio, sr = librosa.load(raw, sr=8000 if telephone else None)
            lead = int(0.3 * sr)  # a prompt's silence around the words
            sf.write(out / f"{name}.wav", np.pad(audio, (lead, lead)), sr)
            script.append(f"{name}: {text}")
            made.append(name)
    (out / "script.txt").write_text("\n".join(script) + "\n", encoding="utf-8")
    return made


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--language", required=True, choices=sorted(VOICES))
    ap.add_argument("--lines", type=int, default=60)
    ap.add_argument("--telephone", action="store_true", help="8 kHz, as a phone prompt library")
    args = ap.parse_args(argv)
    made = build(args.out, args.language, args.lines, args.telephone)
    print(f"{len(made)} lines in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
