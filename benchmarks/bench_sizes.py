"""File size per minute of speech in every output form (what a batch of 10,000 lines costs on disk).

The example line (examples/excellent_room.wav, 4.4 s) and a long clip (the line twelve times, 53 s) are each
animated once with the built-in model and written in each form; the WAV sidecar is counted apart (.glb and
.usdz carry their audio inside as well). Per-file costs (morph targets) dominate short lines.

    python benchmarks/bench_sizes.py [--repeat 12]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FORMS = (  # (file name, write options, what it is)
    ("points.usda", {}, "USD points, text"),
    ("points.usdc", {}, "USD points, binary"),
    ("skel.usdc", {"mode": "blendshapes"}, "UsdSkel blend shapes (PCA), binary"),
    ("arkit.usdc", {"rig": "arkit"}, "UsdSkel, the 52 ARKit shapes"),
    ("points.usdz", {}, "USDZ (points, audio inside)"),
    ("pca.glb", {}, "glTF binary, PCA morph targets (MP3 inside)"),
    ("arkit.glb", {"rig": "arkit"}, "glTF binary, the 52 ARKit shapes (MP3 inside)"),
    ("arkit.json", {}, "ARKit-52 weights, Audio2Face JSON"),
    ("arkit.csv", {}, "ARKit-52 weights, Live Link Face CSV"),
    ("points.npy", {}, "vertex positions, numpy"),
)


def size(paths: list[Path], audio: bool) -> int:
    return sum(p.stat().st_size for p in paths if audio or p.suffix != ".wav")


def measure(repeat: int) -> tuple[float, dict[str, int], int]:
    """Seconds of speech, bytes per form (audio sidecars apart) and the sidecar's bytes for the example line
    said `repeat` times."""
    import soundfile as sf

    from facegen.animator import Animator
    from facegen.exchange import write_animation

    audio, rate = sf.read(ROOT / "examples" / "excellent_room.wav", dtype="float32")
    text = (ROOT / "examples" / "excellent_room.txt").read_text().strip()
    sizes, sidecar = {}, 0
    with tempfile.TemporaryDirectory() as tmp:
        wav = Path(tmp) / "speech.wav"
        sf.write(wav, np.tile(audio, repeat), rate)
        anim = Animator().animate(wav, text=" ".join([text] * repeat))
        for name, options, _ in FORMS:
            written = write_animation(anim, Path(tmp) / name, **options)
            sidecar = max(sidecar, sum(p.stat().st_size for p in written if p.suffix == ".wav"))
            sizes[name] = size(written, audio=False)
    return len(anim.audio) / anim.sample_rate, sizes, sidecar


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=12)
    args = ap.parse_args(argv)
    line_s, line, line_wav = measure(1)
    long_s, long, long_wav = measure(args.repeat)
    print(f"one line: {line_s:.1f} s; long clip: {long_s:.1f} s (the line {args.repeat} times)\n")
    print(f"| form | file | one {line_s:.1f} s line | MB per minute of a {long_s:.0f} s clip | "
          "10,000 such lines |\n|---|---|---|---|---|")
    for name, _, what in FORMS:
        print(f"| {what} | `{name}` | {line[name] / 1e6:.2f} MB | {long[name] / 1e6 / long_s * 60:.2f} | "
              f"{line[name] * 10_000 / 1e9:.1f} GB |")
    per_minute = long_wav / 1e6 / long_s * 60
    print(f"| the WAV sidecar (16-bit) | `.wav` | {line_wav / 1e6:.2f} MB | {per_minute:.2f} | "
          f"{line_wav * 10_000 / 1e9:.1f} GB |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
