"""Benchmark: long recordings (issue 22): seconds, × real time and peak memory of `facegen animate` to ARKit
.json and .npy (with the transcript, without it) and of `facegen align`, on a recording of a given length.

Targets: a 2-hour recording animates to .json and .npy (and aligns) in ≤ 1.5 GB and at ≥ 5× real time.

No hour of recorded speech with its transcript is on the machine, so the recording is made of what is:
Asterisk's recorded prompts with their script (Debian: `apt-get install asterisk-core-sounds-en-wav
asterisk-core-sounds-en`; else sentences spoken by libespeak-ng), in a shuffled loop, separated by pauses of
0.2-1.2 s over a faint noise floor; the transcript is written beside it, and NAME.lines.tsv with each line's
start and end (s). The file is written block by block,
so making two hours at 48 kHz stereo takes little memory.

Each command runs as a new process. "own MB" is its peak RSS as os.wait4 gives it (the largest of the process
and the children it waited for, as /usr/bin/time says): what the 1.5 GB target is about. "peak MB" is the
largest sum of the resident memory of the process and its children (the forked aligner) sampled every 50 ms:
pages the two share after the fork count twice there. A command above --limit MB is killed (a safeguard on a
shared machine); outputs are deleted after each command (a 2-hour .npy takes 50 GB).

    python benchmarks/bench_long.py 1800                 # 30 minutes: every command
    python benchmarks/bench_long.py 7200 --rate 48000 --channels 2 --only json-text
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_mismatch import SCRIPT, SOUNDS, library  # the recorded prompt library and its script

REPO = Path(__file__).resolve().parents[1]
RATE = 16000  # the bank's rate; the file is resampled to --rate


def speech_bank() -> list[tuple[np.ndarray, str]]:
    """(16 kHz audio, its words): Asterisk's recorded English prompts with their recording script (8 kHz
    telephone speech of one professional voice, 540 lines, 24 minutes; the lines with stage directions left
    out), else sentences spoken by libespeak-ng in varied voices."""
    from facegen.audio import load_audio, resample

    if SCRIPT.exists():
        from facegen.words import split_directions

        bank = []
        for _, wav, text in library(SOUNDS, SCRIPT):
            words, directions = split_directions(text)
            if words.strip() and not directions:
                samples, sr = load_audio(wav)
                bank.append((resample(samples, sr, RATE), words))
        return bank
    from facegen.espeak import synthesize
    from facegen.synth.sentences import generated_sentences

    return [(synthesize(text, variant=("m1", "f3", "m3", "f2")[i % 4], pitch=35 + 7 * (i % 5),
                        rate=150 + 10 * (i % 4), sample_rate=RATE).audio, text)
            for i, text in enumerate(generated_sentences(200).values())]


def make_long(path: Path, seconds: float, rate: int = RATE, channels: int = 1, seed: int = 0) -> Path:
    """Write about `seconds` of speech with pauses to the WAV `path` (16-bit PCM) and its transcript to
    path.with_suffix(".txt"); returns the transcript's path."""
    import soundfile as sf

    from facegen.audio import resample

    rng = np.random.default_rng(seed)
    bank = speech_bank()
    words, total, lines = [], 0, []
    with sf.SoundFile(path, "w", samplerate=rate, channels=channels, subtype="PCM_16") as out:
        while total < seconds * RATE:
            for k in rng.permutation(len(bank)):
                audio, text = bank[k]
                pause = int(rng.uniform(0.2, 1.2) * RATE)
                piece = np.concatenate([audio, np.zeros(pause, np.float32)])
                piece = piece + rng.normal(0, 3e-4, len(piece)).astype(np.float32)  # a quiet room
                piece = resample(piece, RATE, rate) if rate != RATE else piece
                out.write(np.repeat(piece[:, None], channels, axis=1) if channels > 1 else piece)
                words.append(text)
                lines.append(f"{total / RATE:.3f}\t{(total + len(audio)) / RATE:.3f}\t{text}")
                total += len(audio) + pause
                if total >= seconds * RATE:
                    break
    txt = path.with_suffix(".txt")
    txt.write_text(" ".join(words) + "\n")
    path.with_suffix(".lines.tsv").write_text("\n".join(lines) + "\n")  # where each line is: the truth
    return txt


# samples the resident memory of a process and its descendants (from /proc) while it runs
_MEASURE = """
import os, subprocess, sys, time
def family_rss(pid):
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        try:
            with open(f"/proc/{p}/statm") as f:
                total += int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
            for t in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{t}/children") as f:
                    todo += [int(c) for c in f.read().split()]
        except (OSError, ValueError):
            pass
    return total
err = open(sys.argv[3], "wb")
proc = subprocess.Popen(sys.argv[4:], stdout=subprocess.DEVNULL, stderr=err)
peak, end = 0, time.monotonic() + float(sys.argv[1])
while not (done := os.wait4(proc.pid, os.WNOHANG))[0]:
    peak = max(peak, family_rss(proc.pid))
    if time.monotonic() > end or peak > float(sys.argv[2]) * 2**20:  # too long, or a danger to the machine
        proc.kill()
    time.sleep(0.05)
print(peak / 2**20, done[2].ru_maxrss / 1024)
sys.exit(os.waitstatus_to_exitcode(done[1]) % 256)
"""


def run(args: list[str], timeout: float, limit_mb: float, log: Path) -> tuple[int, float, float, float, str]:
    """(exit code, wall s, family peak MB, own peak MB, last stderr line) of `args` as a new process, killed
    after `timeout` s or above `limit_mb` (its stderr in `log`)."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _MEASURE, str(timeout), str(limit_mb), str(log), *args],
                          capture_output=True, text=True, cwd=REPO,
                          env=dict(os.environ, HF_HUB_OFFLINE="1", FACEGEN_PROFILE="1"), check=False)
    wall = time.perf_counter() - start
    family, own = (float(x) for x in done.stdout.split()) if done.stdout.strip() else (0.0, 0.0)
    lines = [line for line in log.read_text(errors="replace").splitlines() if len(line) < 2000]
    said = [line for line in lines if not line.startswith('{"facegen_profile"')]
    return done.returncode, wall, family, own, said[-1] if said else "(no message)"


def stages(log: Path) -> str:
    """The stages' seconds from the command's FACEGEN_PROFILE line (facegen.runtime.PROFILE)."""
    for line in reversed(log.read_text(errors="replace").splitlines()):
        if line.startswith('{"facegen_profile"'):
            found = json.loads(line)["facegen_profile"]
            return ", ".join(f"{k} {v:.0f}" for k, v in found.items() if v >= 1)
    return ""


def drift(words_json: Path, lines_tsv: Path) -> str:
    """How far the aligned words lie from the truth: each line's first word's start and last word's end
    against where the line was put (NAME.lines.tsv), as the median and largest error and the lines with
    an edge more than 1 s off."""
    from facegen.words import spoken_words

    words = json.loads(words_json.read_text())["words"]
    errors, k = [], 0
    for row in lines_tsv.read_text().splitlines():
        start, end, text = row.split("\t", 2)
        count = len(spoken_words(text, "en"))
        if count:
            line = words[k:k + count]
            errors.append(max(abs(line[0]["start"] - float(start)), abs(line[-1]["end"] - float(end))))
        k += count
    if k != len(words):
        return f"{len(words)} words aligned, {k} in the lines: not comparable"
    errors = np.array(errors)
    return (f"{len(errors)} lines: edge error median {np.median(errors):.2f} s, max {errors.max():.2f} s, "
            f"{int((errors > 1).sum())} lines with an edge > 1 s off, last line {errors[-1]:.2f} s")


def commands(wav: Path, txt: Path, out: Path) -> dict[str, list[str]]:
    facegen = [sys.executable, "-m", "facegen"]
    return {
        "json-text": [*facegen, "animate", str(wav), "--text-file", str(txt), "-o", str(out / "t.json")],
        "npy-text": [*facegen, "animate", str(wav), "--text-file", str(txt), "-o", str(out / "t.npy")],
        "json-notext": [*facegen, "animate", str(wav), "-o", str(out / "n.json")],
        "npy-notext": [*facegen, "animate", str(wav), "-o", str(out / "n.npy")],
        "align": [*facegen, "align", str(wav), "--text-file", str(txt), "-o", str(out / "words.json")],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("seconds", type=float, help="length of the recording")
    parser.add_argument("--rate", type=int, default=RATE, help="its sample rate (Hz)")
    parser.add_argument("--channels", type=int, default=1)
    parser.add_argument("--only", nargs="*", help="commands to run (default: all): json-text npy-text "
                                                  "json-notext npy-notext align")
    parser.add_argument("--folder", type=Path, default=Path("/tmp/facegen-bench-long"))
    parser.add_argument("--timeout", type=float, default=7200.0, help="seconds before a command is killed")
    parser.add_argument("--limit", type=float, default=4096.0, help="MB of memory at which it is killed")
    args = parser.parse_args()
    args.folder.mkdir(parents=True, exist_ok=True)
    wav = args.folder / f"long-{args.seconds:g}s-{args.rate}-{args.channels}ch.wav"
    txt = wav.with_suffix(".txt")
    if not (wav.exists() and txt.exists()):
        start = time.perf_counter()
        make_long(wav, args.seconds, args.rate, args.channels)
        print(f"made {wav} in {time.perf_counter() - start:.0f} s", file=sys.stderr)
    out = args.folder / "out"
    out.mkdir(exist_ok=True)
    todo = commands(wav, txt, out)
    print(f"{args.seconds:g} s recording, {args.rate} Hz, {args.channels} channel(s); load "
          f"{os.getloadavg()[0]:.2f} at start", flush=True)
    print(f"{'command':<12} {'exit':>4} {'seconds':>8} {'x real':>7} {'peak MB':>8} {'own MB':>7}  target")
    for name, command in todo.items():
        if args.only and name not in args.only:
            continue
        code, wall, family, own, said = run(command, args.timeout, args.limit, out / f"{name}.log")
        ok = code == 0 and own <= 1536 and args.seconds / wall >= 5
        print(f"{name:<12} {code:>4} {wall:>8.1f} {args.seconds / wall:>7.1f} {family:>8.0f} {own:>7.0f}  "
              f"{'ok' if ok else 'MISSED'}  load {os.getloadavg()[0]:.2f}", flush=True)
        print(f"   {said if code else stages(out / f'{name}.log')}", flush=True)
        if name == "align" and code == 0:
            print(f"   {drift(out / 'words.json', wav.with_suffix('.lines.tsv'))}", flush=True)
        for output in out.glob("[tn].*"):  # a 2-hour .npy takes 50 GB
            output.unlink()


if __name__ == "__main__":
    main()
