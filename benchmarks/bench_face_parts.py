"""The parts beside the face (facegen.face.parts) on the example sentence: how far each lies behind the skin
looking from the front (facegen.face.parts.skin_clearance, every frame), and the bytes they add to a .usdc
and a .glb. Run: python benchmarks/bench_face_parts.py [AUDIO TRANSCRIPT]."""

from __future__ import annotations

import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

import facegen
from facegen.face.parts import skin_clearance
from facegen.face.rig import face_scale

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str]) -> None:
    audio = Path(argv[0]) if argv else REPO / "examples" / "excellent_room.wav"
    transcript = Path(argv[1]) if len(argv) > 1 else REPO / "examples" / "excellent_room.txt"
    text = transcript.read_text()
    anim = facegen.animate(audio, text=text, seed=0)
    _, cm = face_scale(anim.template, anim.regions)
    worst: dict[str, tuple[float, int]] = {}
    for t in range(anim.num_frames):
        frame = np.asarray(anim.vertices[t])
        for track in anim.part_meshes():
            d = float(skin_clearance(frame, anim.faces, anim.regions, track.points(t)).min())
            d = d / cm * 10
            if d < worst.get(track.part.name, (np.inf, 0))[0]:
                worst[track.part.name] = (d, t)
    print(f"{anim.num_frames} frames ({anim.duration:.2f} s); clearance behind the skin, from the front:")
    for name, (mm, t) in worst.items():
        print(f"  {name:11s} {mm:7.2f} mm at its closest (frame {t})")
    with tempfile.TemporaryDirectory() as folder:
        for suffix in (".usdc", ".glb"):
            sizes = []
            for clip in (anim, replace(anim, parts=None)):
                path = Path(folder) / f"face{suffix}"
                facegen.write_animation(clip, path)
                sizes.append(path.stat().st_size)
            print(f"  {suffix}: {sizes[0] / 1e6:.2f} MB with the parts, {sizes[1] / 1e6:.2f} MB without "
                  f"(+{(sizes[0] - sizes[1]) / 1e3:.0f} KB)")


if __name__ == "__main__":
    main(sys.argv[1:])
