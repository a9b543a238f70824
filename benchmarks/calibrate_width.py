"""Calibrate how far the rig's rounding and spreading move the mouth's corners (issue 23) on GRID's speakers.

Input: a result of `python benchmarks/real_faces.py` (benchmarks/results/real_faces_NAME.json): per clip the
phones facegen's aligner found and, at the middle of each vowel, how much wider or narrower than at rest the
tracker saw the real speaker's mouth (MediaPipe corners 61-291, cm on the iris scale). For each pair of
values of facegen.face.rig.ROUND_NARROW and WIDE_SPREAD the rig is built again, posed from the clips' phones,
loudness and formants (facegen.synth.curves.viseme_curves, the corpus's code) and its mouth width read off the
mesh (facegen.lipsync.mouth_width, corner to corner, change from the neutral face) at the same moments.

The score is the root mean square, over spread, rounded, UW and IY vowels, of the difference between the
rig's and the speakers' median width change, each taken against its own open-and-mid baseline (the jaw moves
the corners a little too; the contrast is what rounding and spreading add). Every other clip (sorted by name)
is a half; the score is printed on all clips and on each half, so a value that only fits one half shows.

    python benchmarks/calibrate_width.py [benchmarks/results/real_faces_default.json]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROUND = (0.36, 0.2, 0.15, 0.11, 0.08, 0.05)  # ROUND_NARROW values tried (0.36: before the calibration)
SPREAD = (0.24, 0.1, 0.05, 0.025, 0.0)  # WIDE_SPREAD values tried (0.24: before)
GROUPS = ("open", "mid", "spread", "rounded", "UW", "IY")  # classes of real_faces_measures, then visemes


def rig_widths(clips: list[dict], vowels: list[list[dict]], round_narrow: float,
               wide_spread: float) -> list[list[float]]:
    """Per clip, the rig's mouth width change (cm) at the moment `t` of each of its `vowels` rows."""
    from facegen.face import rig as rig_module
    from facegen.face.template import load_template
    from facegen.lipsync import FaceGeometry, mouth_width
    from facegen.synth.curves import viseme_curves

    old = rig_module.ROUND_NARROW, rig_module.WIDE_SPREAD
    rig_module.ROUND_NARROW, rig_module.WIDE_SPREAD = round_narrow, wide_spread
    try:
        mesh = load_template()
        rig, geo = rig_module.Rig(mesh), FaceGeometry.of(mesh)
    finally:
        rig_module.ROUND_NARROW, rig_module.WIDE_SPREAD = old
    neutral = float(mouth_width(rig.template[None], geo)[0])
    n_lower = len(rig_module.LOWER_CHANNELS)
    out = []
    for clip, rows in zip(clips, vowels):
        n = len(clip["real"])
        weights = np.zeros((n, len(rig_module.CHANNELS)), np.float32)
        weights[:, :n_lower] = viseme_curves(clip["phones"], n, 25.0, alphabet="cmu",
                                             loudness=clip["loudness"], f1=clip["f1"])
        width = mouth_width(rig.pose(weights), geo) - neutral
        out.append([float(np.interp(row["t"] * 25.0, np.arange(n), width)) for row in rows])
    return out


def medians(vowels: list[list[dict]], widths: list[list[float]],
            keep: set[int] | None = None) -> dict[str, tuple[int, float, float]]:
    """{group: (n, real median, rig median)} of the width changes over the clips in `keep` (all: None); a
    vowel counts in its class (real_faces_measures.VOWEL_CLASSES) and, for UW and IY, on its own too."""
    from real_faces_measures import vowel_class

    found: dict[str, list[tuple[float, float]]] = {}
    for k, (rows, ours) in enumerate(zip(vowels, widths)):
        if keep is not None and k not in keep:
            continue
        for row, w in zip(rows, ours):
            for group in {vowel_class(row["viseme"]), row["viseme"]} & set(GROUPS):
                found.setdefault(group, []).append((float(row["width_change"]), w))
    return {g: (len(pairs), float(np.median([a for a, _ in pairs])), float(np.median([b for _, b in pairs])))
            for g, pairs in ((g, found[g]) for g in GROUPS if g in found)}


def score(found: dict) -> float:
    """RMS (cm) of rig minus real over spread, rounded, UW, IY, each against its open-and-mid baseline."""
    base = [np.mean([found[g][i] for g in ("open", "mid")]) for i in (1, 2)]
    diffs = [(found[g][2] - base[1]) - (found[g][1] - base[0]) for g in ("spread", "rounded", "UW", "IY")
             if g in found]
    return float(np.sqrt(np.mean(np.square(diffs))))


def main(argv: list[str] | None = None) -> int:
    import json

    from calibrate_rig import load

    from facegen.face.rig import ROUND_NARROW, WIDE_SPREAD

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("result", type=Path, nargs="?", default=HERE / "results" / "real_faces_default.json")
    args = ap.parse_args(argv)
    clips = load(args.result)
    saved = json.loads(args.result.read_text())["clips"]
    vowels = [saved[clip["name"]]["vowels_real"] for clip in clips]
    halves = set(range(0, len(clips), 2)), set(range(1, len(clips), 2))
    print(f"{len(clips)} clips; shipped ROUND_NARROW {ROUND_NARROW}, WIDE_SPREAD {WIDE_SPREAD}")
    print("| ROUND_NARROW | WIDE_SPREAD | score all / even / odd (cm) | "
          + " | ".join(f"{g} real / rig" for g in GROUPS) + " |")
    print("|---|---|---|" + "---|" * len(GROUPS))
    for r in ROUND:
        for s in SPREAD:
            widths = rig_widths(clips, vowels, r, s)
            found = medians(vowels, widths)
            scores = " / ".join(f"{score(medians(vowels, widths, h)):.3f}" for h in (None, *halves))
            cells = " | ".join(f"{found[g][1]:+.2f} / {found[g][2]:+.2f}" for g in GROUPS if g in found)
            print(f"| {r:.3f} | {s:.3f} | {scores} | {cells} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
