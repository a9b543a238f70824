"""Set how the rig's lips part between the jaw and the lower lip, on a real ARKit take (issue 23,
docs/arkit_capture.md): the rig's jaw_open turns the jaw (facegen.face.rig.JAW_MAX_ANGLE) and drops the lower
lip further on its own (LIP_DROP_CM). An iPhone reads the first as jawOpen and the second as mouthLowerDown; a
real speaker's lower lip drops with the jaw (mouthLowerDown follows jawOpen at r 0.68 in the take measured).

For each share s of the lips' opening at jaw_open 1 given to the lower lip's own drop (the opening itself kept
at the shipped rig's), the rig is driven by the phones facegen recognises in the take's audio (its loudness,
the default speaker's style), solved into ARKit weights as facegen's output is, and laid beside the capture:
jawOpen's r (lag 0 and the best within +-120 ms) and its 5th-95th range against the capture's,
mouthLowerDown's 95th percentile and its slope on jawOpen against the capture's. With --real-faces the rig's
geometric lip aperture on the GRID clips too (r, median ratio: calibrate_rig.py's measure), which the split
should leave alone.

    python benchmarks/calibrate_lip_drop.py TAKE.csv TAKE.wav [--shares 0 0.1 0.17 0.25] [--real-faces R.json]

The capture's lower lip gives two figures: mouthLowerDown's 95th percentile, and how far it drops per jawOpen
with the smile regressed out (a smile lowers the lower lip too). The rig's 95th percentile matches the
capture's at a share of 0.10 on the take measured (the slope asks for a little less); the shipped share is
0.15, where the model trained on the rig (which draws the lip less far than its rig) comes near it.
"""

from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import arkit_capture
import calibrate_rig
from real_faces_measures import best_of, lag_curve


def _gap(rig, geo, jaw_open: float = 1.0) -> float:
    """The lips' opening (cm, facegen.lipsync.aperture) of `rig` at `jaw_open`, the rest at 0."""
    from facegen.face.rig import CHANNELS
    from facegen.lipsync import aperture

    w = np.zeros((1, len(CHANNELS)), np.float32)
    w[0, CHANNELS.index("jaw_open")] = jaw_open
    return float(aperture(rig.pose(w), geo)[0])


@contextmanager
def split(angle: float, drop_cm: float):
    """The rig's JAW_MAX_ANGLE and LIP_DROP_CM (and ARKit's jawOpen scale, which follows the angle) set."""
    from facegen.arkit import deformers
    from facegen.face import rig

    old = rig.JAW_MAX_ANGLE, rig.LIP_DROP_CM, deformers.JAW_OPEN_SCALE
    rig.JAW_MAX_ANGLE, rig.LIP_DROP_CM = angle, drop_cm
    deformers.JAW_OPEN_SCALE = deformers.JAW_OPEN_ANGLE / angle
    try:
        yield
    finally:
        rig.JAW_MAX_ANGLE, rig.LIP_DROP_CM, deformers.JAW_OPEN_SCALE = old


def _bisect(f, lo: float, hi: float, target: float, steps: int = 30) -> float:
    """x in [lo, hi] where the increasing f(x) = target."""
    for _ in range(steps):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if f(mid) < target else (lo, mid)
    return (lo + hi) / 2


def for_share(share: float, mesh, geo, total_cm: float) -> tuple[float, float]:
    """(JAW_MAX_ANGLE, LIP_DROP_CM) that open the lips `total_cm` at jaw_open 1, the jaw's turn (1 - share)
    of it."""
    from facegen.face.rig import Rig

    def turn_gap(angle: float) -> float:
        with split(angle, 0.0):
            return _gap(Rig(mesh), geo)

    rest = _gap(Rig(mesh), geo, 0.0)
    angle = _bisect(turn_gap, 0.0, 0.6, rest + (1 - share) * (total_cm - rest))

    def gap(drop: float) -> float:
        with split(angle, drop):
            return _gap(Rig(mesh), geo)

    return angle, (_bisect(gap, 0.0, 2.0, total_cm) if share > 0 else 0.0)


def teacher_on_take(take: calibrate_rig.Capture, mesh) -> dict[str, np.ndarray]:
    """The rig's face from the take's recognised phones (the default speaker's style, the take's loudness and
    formants), solved into ARKit weights with shapes built on the rig as it is set now: {ARKit name: [T]}."""
    from facegen.animation import Animation
    from facegen.arkit.shapes import build_shapes
    from facegen.arkit.solve import fit_arkit
    from facegen.face.rig import Rig
    from facegen.synth.corpus import TRAIN_SPEAKERS, speaker_index
    from facegen.synth.curves import SpeakerStyle
    from facegen.synth.reference import rig_reference

    style = SpeakerStyle.for_speaker(speaker_index(TRAIN_SPEAKERS[0]))  # a model's first speaker: its default
    vertices = rig_reference(take.phones, [], take.n, 25.0, Rig(mesh), alphabet="cmu", loudness=take.loudness,
                             f1=take.f1, style=style)
    anim = Animation(vertices=vertices, faces=mesh.faces, fps=25.0,
                     template=np.asarray(mesh.vertices, np.float32), regions=mesh.regions)
    fit = fit_arkit(anim, shapes=build_shapes(mesh))
    return {name: fit.weights[:, i] for i, name in enumerate(fit.names)}


def _range(x: np.ndarray) -> float:
    p5, p95 = np.percentile(x, [5, 95])
    return float(p95 - p5)


def _smile(weights: dict) -> np.ndarray:
    return (weights["mouthSmileLeft"] + weights["mouthSmileRight"]) / 2


def lower_per_jaw(lower: np.ndarray, jaw: np.ndarray, smile: np.ndarray | None = None) -> float:
    """How far the lower lip drops per jawOpen: the slope of mouthLowerDown on jawOpen (least squares, with an
    offset), the smile regressed out beside it when given (a smile shows the lower teeth too: in the take
    measured, mouthLowerDown ~ 0.85 jawOpen + 0.56 mouthSmile)."""
    cols = [jaw] + ([smile] if smile is not None else []) + [np.ones_like(jaw)]
    coef, *_ = np.linalg.lstsq(np.stack(cols, 1), lower, rcond=None)
    return float(coef[0])


def measure(share: float, take, capture: dict, mesh, geo, total_cm: float, clips=None) -> dict:
    angle, drop = for_share(share, mesh, geo, total_cm)
    with split(angle, drop):
        fg = teacher_on_take(take, mesh)
        grid = None
        if clips:
            from facegen.face.rig import Rig

            scorer = calibrate_rig.Scorer()
            scorer.rig = Rig(mesh)
            start = {k: (v[0] if v[0] is not None else calibrate_rig.shipped(k))
                     for k, v in calibrate_rig.PARAMS.items()}
            grid = scorer.measure(clips, start)
    jaw, cap_jaw = fg["jawOpen"], capture["jawOpen"]
    curve = lag_curve(jaw, cap_jaw, 25.0, calibrate_rig.Capture.MAX_LAG / 25.0)
    best_r, _ = best_of(curve)
    lower = (fg["mouthLowerDownLeft"] + fg["mouthLowerDownRight"]) / 2
    cap_lower = (capture["mouthLowerDownLeft"] + capture["mouthLowerDownRight"]) / 2
    return {"share": share, "jaw_max_angle": angle, "lip_drop_cm": drop, "lower_down_per_jaw":
            lower_per_jaw(lower, jaw), "capture_lower_down_per_jaw": lower_per_jaw(cap_lower, cap_jaw,
                                                                                   _smile(capture)),
            "jaw_r": float(np.corrcoef(jaw, cap_jaw)[0, 1]), "jaw_r_best": best_r,
            "jaw_range_ratio": _range(jaw) / _range(cap_jaw),
            "lower_down_p95": float(np.percentile(lower, 95)), "capture_lower_down_p95":
            float(np.percentile(cap_lower, 95)),
            "grid_r": None if grid is None else grid["r"],
            "grid_ratio": None if grid is None else grid["ratio"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("csv", type=Path)
    ap.add_argument("wav", type=Path)
    ap.add_argument("--shares", type=float, nargs="+", default=[0.0, 0.1, 0.17, 0.25])
    ap.add_argument("--real-faces", type=Path, help="a real_faces.py result: the GRID clips' aperture too")
    args = ap.parse_args(argv)

    from facegen.face.rig import Rig
    from facegen.face.template import load_template
    from facegen.lipsync import FaceGeometry

    mesh = load_template()
    geo = FaceGeometry.of(mesh)
    total = _gap(Rig(mesh), geo)
    take = calibrate_rig.Capture(args.csv, args.wav)
    track = arkit_capture.read_capture(args.csv)
    frames = arkit_capture.on_frames(track, 25.0, take.n)
    capture = {name: frames[:, i] for i, name in enumerate(track.names)}
    clips = calibrate_rig.load(args.real_faces) if args.real_faces else None
    print(f"the lips part {total:.2f} cm at jaw_open 1 (kept); the capture's mouthLowerDown p95 "
          f"{np.percentile((capture['mouthLowerDownLeft'] + capture['mouthLowerDownRight']) / 2, 95):.2f}")
    print("share  jaw angle  lip drop | jawOpen r lag0/best  range/capture | mouthLowerDown p95, per jawOpen "
          "| GRID r  ratio")
    for share in args.shares:
        m = measure(share, take, capture, mesh, geo, total, clips)
        grid = "" if m["grid_r"] is None else f" | {m['grid_r']:.3f}  {m['grid_ratio']:.3f}"
        print(f"{share:5.2f}  {m['jaw_max_angle']:.3f} rad  {m['lip_drop_cm']:.2f} cm | "
              f"{m['jaw_r']:.3f} / {m['jaw_r_best']:.3f}  {m['jaw_range_ratio']:.2f} | "
              f"{m['lower_down_p95']:.2f}, {m['lower_down_per_jaw']:.2f} "
              f"(capture {m['capture_lower_down_p95']:.2f}, {m['capture_lower_down_per_jaw']:.2f}){grid}",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
