"""Calibrate the rig's lips on real faces (issue 23): fit the rig's opening and timing parameters so that its
lip aperture follows the real one tracked in the GRID clips of benchmarks/real_faces.py.

Input: a result of `python benchmarks/real_faces.py` (benchmarks/results/real_faces_NAME.json), which holds,
per clip, the real inner-lip aperture tracked with MediaPipe (cm on the iris scale, 25 fps) and the phones
facegen's aligner found in its audio. For a set of parameters the rig's curves are rebuilt from those phones
(facegen.synth.curves.viseme_curves, the synthetic corpus's own code), posed on the procedural face and
measured geometrically (facegen.lipsync.aperture, cm). The fit maximises the aperture correlation and brings
the median open-speech ratio to 1 on half the clips (every other one, sorted by name) and reports both halves,
so the held-out half says whether it generalises.

The parameters (facegen.synth.curves): a gain on every vowel's jaw opening and one per vowel class (open,
mid, spread, rounded), the consonants' jaw dominance (how much a consonant between two vowels closes the jaw),
the anticipation and carry-over time constants of coarticulation (the jaw's anticipation apart), the jaw
opening of the in-breath before speech after a pause, the lips' ramp into and out of a p/b/m and how much
a vowel's first formant opens its jaw (formant_exp; the rig reads each clip's loudness and formants). Bounds
keep them physical (see docs/real_faces.md for the published figures they are held against).

    python benchmarks/calibrate_rig.py [benchmarks/results/real_faces_default.json] [--evals 300]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
CLASSES = {"open": ("AA", "AE", "AO"), "mid": ("EH", "ER", "OW"), "schwa": ("AH",), "spread": ("IY", "IH"),
           "rounded": ("UW", "UH")}  # schwa apart: reduced in running speech (function words), full in GRID
# name: (start, low, high); gains multiply the shipped rig's values (1: as shipped), the rest replace them.
# The shipped rig is the result of `--start` from an earlier fit on the rig before calibration (fit r 0.43 ->
# 0.58, held out 0.62 -> 0.70; docs/real_faces.md).
PARAMS = {
    "jaw_gain": (1.0, 0.6, 2.5),
    "open": (1.0, 0.6, 1.6),
    "mid": (1.0, 0.6, 1.6),
    "schwa": (1.0, 0.3, 1.6),
    "spread": (1.0, 0.6, 2.0),  # GRID's /i/ (letters read aloud: "e", "three") opens unusually wide
    "rounded": (1.0, 0.6, 2.0),
    "consonant_jaw_dominance": (1.0, 0.2, 1.5),
    "anticipation_s": (None, 0.03, 0.15),  # None: the shipped value (facegen.synth.curves)
    "jaw_anticipation_s": (None, 0.02, 0.15),  # the jaw's own (JAW_ANTICIPATION_S)
    "carryover_s": (None, 0.015, 0.12),
    "pre_speech_jaw": (None, 0.0, 0.3),
    "close_ramp_s": (None, 0.01, 0.06),
    "round_close": (None, 0.0, 0.9),  # rounded lips pursed (facegen.synth.curves.ROUND_CLOSE)
    "w_close": (None, 0.0, 0.6),  # W's own lip_close (beside its rounding)
    "fv_close": (None, 0.0, 1.0),  # f/v's lip_close: the lower lip up against the upper teeth
    "formant_exp": (None, 0.0, 3.0),  # a vowel's jaw x (its F1 / its usual F1) ** this (FORMANT_EXP)
}
# parameters that are entries of the VISEMES table
TABLE = {"w_close": ("W", "lip_close"), "fv_close": ("FV", "lip_close")}
OPEN_CM = 0.2  # real aperture above which a frame is open speech (as real_faces.py)


def load(path: Path) -> list[dict]:
    """The clips: name, real aperture [T] (cm), phones [(CMU, start, end)], words, fps 25, and the rig's
    readings of the clip's audio (benchmarks/data/grid/NAME.mpg), its loudness and first formant (the corpus's
    rig reads both)."""
    import tempfile

    from real_faces import DATA, extract_audio

    from facegen.audio import load_audio
    from facegen.synth.curves import formant_track, loudness_envelope

    result = json.loads(path.read_text())
    clips = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, clip in sorted(result["clips"].items()):
            real = np.asarray(clip["tracks"]["real"]["aperture"], np.float64)
            wav = Path(tmp) / f"{name}.wav"
            extract_audio(DATA / f"{name}.mpg", wav)
            audio, sr = load_audio(wav)
            clips.append({"name": name, "real": real, "phones": [tuple(p) for p in clip["phones"]],
                          "words": clip["words"], "loudness": loudness_envelope(audio, sr),
                          "f1": formant_track(audio, sr)})
    return clips


def apply(params: dict) -> dict:
    """Set the rig's parameters in facegen.synth.curves (a fit, not the shipped values); the old ones back."""
    from facegen.face.rig import LOWER_CHANNELS
    from facegen.synth import curves

    old = {"VISEMES": dict(curves.VISEMES), "ANTICIPATION_S": curves.ANTICIPATION_S,
           "JAW_ANTICIPATION_S": curves.JAW_ANTICIPATION_S,
           "CARRYOVER_S": curves.CARRYOVER_S, "PRE_SPEECH_JAW": curves.PRE_SPEECH_JAW,
           "CLOSE_RAMP_S": curves.CLOSE_RAMP_S, "ROUND_CLOSE": curves.ROUND_CLOSE,
           "FORMANT_EXP": curves.FORMANT_EXP}
    visemes = dict(old["VISEMES"])
    for vis, (target, dom_jaw, dom_lips) in old["VISEMES"].items():
        target = target.copy()
        cls = next((c for c, members in CLASSES.items() if vis in members), None)
        if cls is not None:
            target[0] = min(target[0] * params["jaw_gain"] * params[cls], 1.0)
        elif vis not in ("rest", "PBM"):
            dom_jaw = dom_jaw * params["consonant_jaw_dominance"]
        for name, (entry, channel) in TABLE.items():
            if vis == entry:
                target[LOWER_CHANNELS.index(channel)] = params[name]
        visemes[vis] = (target, dom_jaw, dom_lips)
    curves.VISEMES = visemes
    curves.ANTICIPATION_S = params["anticipation_s"]
    curves.JAW_ANTICIPATION_S = params["jaw_anticipation_s"]
    curves.CARRYOVER_S = params["carryover_s"]
    curves.PRE_SPEECH_JAW = params["pre_speech_jaw"]
    curves.CLOSE_RAMP_S = params["close_ramp_s"]
    curves.ROUND_CLOSE = params["round_close"]
    curves.FORMANT_EXP = params["formant_exp"]
    return old


def shipped(name: str) -> float:
    """The rig's value today of parameter `name` (a constant of facegen.synth.curves or a VISEMES entry)."""
    from facegen.face.rig import LOWER_CHANNELS
    from facegen.synth import curves

    if name in TABLE:
        entry, channel = TABLE[name]
        return float(curves.VISEMES[entry][0][LOWER_CHANNELS.index(channel)])
    return getattr(curves, name.upper())


def restore(old: dict) -> None:
    from facegen.synth import curves

    for key, value in old.items():
        setattr(curves, key, value)


class Scorer:
    """The rig's aperture for every clip under a set of parameters, and how it compares with the real one."""

    def __init__(self) -> None:
        from facegen.face.rig import CHANNELS, LOWER_CHANNELS
        from facegen.lipsync import FaceGeometry
        from facegen.synth.reference import _template_rig

        self.rig = _template_rig()
        self.geo = FaceGeometry.of(self.rig.mesh if hasattr(self.rig, "mesh") else _mesh())
        self.n_channels, self.n_lower = len(CHANNELS), len(LOWER_CHANNELS)

    def aperture(self, clip: dict) -> np.ndarray:
        from facegen.lipsync import aperture
        from facegen.synth.curves import viseme_curves

        lower = viseme_curves(clip["phones"], len(clip["real"]), 25.0, alphabet="cmu",
                              loudness=clip.get("loudness"), f1=clip.get("f1"))
        weights = np.zeros((len(lower), self.n_channels))
        weights[:, :self.n_lower] = lower
        return aperture(self.rig.pose(weights), self.geo)

    def measure(self, clips: list[dict], params: dict) -> dict:
        old = apply(params)
        try:
            rs, ratios = [], []
            for clip in clips:
                ours, real = self.aperture(clip), clip["real"]
                rs.append(float(np.corrcoef(ours, real)[0, 1]))
                open_ = real > OPEN_CM
                ratios.append(float(np.median(ours[open_] / real[open_])) if open_.any() else 1.0)
        finally:
            restore(old)
        return {"r": float(np.mean(rs)), "ratio": float(np.median(ratios)), "rs": rs}


def per_phone(scorer: Scorer, clips: list[dict], params: dict) -> dict[str, tuple[int, float, float]]:
    """{phone: (occurrences, real aperture, rig aperture)}: medians (cm) at the phones' middles in `clips`."""
    old = apply(params)
    try:
        found: dict[str, list[tuple[float, float]]] = {}
        for clip in clips:
            ours, real = scorer.aperture(clip), clip["real"]
            t = np.arange(len(real)) / 25.0
            for phone, start, end in clip["phones"]:
                middle = (start + end) / 2
                found.setdefault(phone.rstrip("012"), []).append((np.interp(middle, t, real),
                                                                  np.interp(middle, t, ours)))
    finally:
        restore(old)
    return {p: (len(v), float(np.median([a for a, _ in v])), float(np.median([b for _, b in v])))
            for p, v in sorted(found.items(), key=lambda kv: -len(kv[1]))}


def _mesh():
    from facegen.face.template import load_template

    return load_template()


def loss(measured: dict) -> float:
    return (1.0 - measured["r"]) + 0.5 * abs(np.log(max(measured["ratio"], 1e-3)))


def fit(scorer: Scorer, clips: list[dict], evals: int, start: dict, names: list[str] | None = None,
        capture: Capture | None = None, weight: float = 1.0) -> dict:
    """Nelder-Mead on the parameters `names` (default: all), the others held at `start`; with a `capture`,
    `weight` x (1 - the rig's jaw r on its first half) is added to the loss."""
    from scipy.optimize import minimize

    names = names or list(PARAMS)
    low = np.array([PARAMS[n][1] for n in names])
    high = np.array([PARAMS[n][2] for n in names])

    def unpack(x: np.ndarray) -> dict:
        return {**start, **dict(zip(names, np.clip(x, low, high), strict=True))}

    def objective(x: np.ndarray) -> float:
        penalty = float(np.sum(np.maximum(low - x, 0) + np.maximum(x - high, 0))) * 10
        extra = weight * (1.0 - capture.r(unpack(x), 0)) if capture is not None else 0.0
        return loss(scorer.measure(clips, unpack(x))) + extra + penalty

    x0 = np.array([start[n] for n in names])
    # first steps of a tenth of each parameter's range (scipy's 5 % of the value never moves one that is 0)
    simplex = np.vstack([x0, x0 + np.diag((high - low) / 10)])
    found = minimize(objective, x0, method="Nelder-Mead",
                     options={"maxfev": evals, "xatol": 1e-3, "fatol": 1e-4, "initial_simplex": simplex})
    return {k: round(float(v), 4) for k, v in unpack(found.x).items()}


class Capture:
    """A real ARKit take with its audio (a Live Link Face CSV and WAV, as benchmarks/arkit_capture.py reads
    them): the capture's jawOpen on 25 fps frames, and the phones facegen aligns to the words it recognises in
    the audio (natural speech has no transcript). The rig's jaw_open from those phones is held against the
    capture's jawOpen: Pearson r at the best lag within MAX_LAG frames (the capture may trail its audio by a
    tracking latency, docs/arkit_capture.md), on the take's first half (fitted) or its second (held out)."""

    MAX_LAG = 3  # frames (120 ms)

    def __init__(self, csv_path: Path, wav_path: Path) -> None:
        import arkit_capture

        from facegen.audio import load_audio
        from facegen.runtime import SILENT
        from facegen.synth.curves import formant_track, loudness_envelope
        from facegen.word_timing import clip_words_and_phones

        take = arkit_capture.read_capture(csv_path)
        audio, sr = load_audio(wav_path)
        self.n = int(min(take.times[-1], len(audio) / sr) * 25.0)
        self.jaw = arkit_capture.on_frames(take, 25.0, self.n)[:, take.names.index("jawOpen")]
        timing = clip_words_and_phones(audio, sr, self.n, 25.0, text=None, alignment=None, no_text=True,
                                       reporter=SILENT)
        self.phones = timing.phone_times or []
        self.loudness, self.f1 = loudness_envelope(audio, sr), formant_track(audio, sr)

    def rig_jaw(self, params: dict) -> np.ndarray:
        from facegen.synth.curves import viseme_curves

        old = apply(params)
        try:
            return viseme_curves(self.phones, self.n, 25.0, alphabet="cmu", loudness=self.loudness,
                                 f1=self.f1)[:, 0]
        finally:
            restore(old)

    def r(self, params: dict, half: int) -> float:
        """The best-lag r of the rig's jaw_open with the capture's jawOpen over `half` (0: first half)."""
        ours = self.rig_jaw(params)
        cut = self.n // 2
        part = slice(0, cut) if half == 0 else slice(cut, self.n)
        a, b = ours[part], self.jaw[part]
        best = -1.0
        for lag in range(-self.MAX_LAG, self.MAX_LAG + 1):  # + : the rig late
            x, y = (a[lag:], b[:len(b) - lag]) if lag >= 0 else (a[:lag], b[-lag:])
            best = max(best, float(np.corrcoef(x, y)[0, 1]))
        return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("result", type=Path, nargs="?", default=HERE / "results" / "real_faces_default.json")
    ap.add_argument("--evals", type=int, default=300)
    ap.add_argument("--json", type=Path, help="write the fitted parameters and the figures here")
    ap.add_argument("--start", type=Path, help="start from the parameters of an earlier fit (its --json)")
    ap.add_argument("--phones", action="store_true",
                    help="print the real and the rig's aperture per phone (the started parameters) and stop")
    ap.add_argument("--fit", help="fit only these parameters (comma-separated names), the others as started")
    ap.add_argument("--capture", nargs=2, type=Path, metavar=("CSV", "WAV"),
                    help="also follow the jaw of a real ARKit take with its audio (Live Link Face CSV "
                    "and WAV): the rig's jaw_open against its jawOpen, first half fitted, second held out")
    ap.add_argument("--capture-weight", type=float, default=1.0,
                    help="weight of the take's (1 - r) in the loss beside the GRID clips' (default 1)")
    args = ap.parse_args(argv)
    clips = load(args.result)
    fit_on, held_out = clips[0::2], clips[1::2]
    scorer = Scorer()
    start = {n: v[0] if v[0] is not None else shipped(n) for n, v in PARAMS.items()}
    begin = {**start, **(json.loads(args.start.read_text())["params"] if args.start else {})}
    t0 = time.perf_counter()
    if args.phones:
        print("| phone | n | real (cm) | rig (cm) |\n|---|---|---|---|")
        for phone, (n, real, ours) in per_phone(scorer, clips, begin).items():
            print(f"| {phone} | {n} | {real:.2f} | {ours:.2f} |")
        return 0
    names = args.fit.split(",") if args.fit else None
    unknown = sorted(set(names or ()) - set(PARAMS))
    if unknown:
        ap.error(f"unknown parameter(s) {', '.join(unknown)}; choose from {', '.join(PARAMS)}")
    capture = Capture(*args.capture) if args.capture else None
    params = fit(scorer, fit_on, args.evals, begin, names, capture, args.capture_weight)
    rows = {}
    for label, p in (("today's rig", start), ("fitted", params)):
        rows[label] = {part: scorer.measure(group, p) for part, group in (("fit", fit_on),
                                                                           ("held out", held_out))}
        if capture is not None:
            rows[label]["capture"] = {"fit": capture.r(p, 0), "held out": capture.r(p, 1)}
    print(f"{len(clips)} clips ({len(fit_on)} fit, {len(held_out)} held out), "
          f"{time.perf_counter() - t0:.0f} s")
    head = "| rig | fit: r | fit: ratio | held out: r | held out: ratio |"
    print(head + (" take's jaw r: fit half | held-out half |" if capture else "")
          + "\n|---|---|---|---|---|" + ("---|---|" if capture else ""))
    for label, m in rows.items():
        take = f" {m['capture']['fit']:.2f} | {m['capture']['held out']:.2f} |" if capture else ""
        print(f"| {label} | {m['fit']['r']:.2f} | {m['fit']['ratio']:.2f} | {m['held out']['r']:.2f} | "
              f"{m['held out']['ratio']:.2f} |" + take)
    print("fitted:", json.dumps(params))
    if args.json:
        args.json.write_text(json.dumps({"params": params, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
