"""facegen's ARKit weights against a real iPhone capture of the same speech (issue 23, "Deliver 3").

A Live Link Face take (the app's CSV: Timecode, BlendShapeCount, the 52 shapes in UpperCamel, head and eye
rotations) records what ARKit's face tracker read from a real face while the person spoke; the take's audio
(the .mov's sound track, saved as WAV/FLAC) is the speech. facegen animates that audio (`facegen animate
AUDIO -o OUT.json`, the Audio2Face JSON of its 52-shape fit, arkit/solve.py) and both weight tracks are put
side by side on facegen's frames:

* the capture is box-averaged over each facegen frame (60 fps -> 25 fps) at the Timecodes' times, its first
  row at the audio's start (the app starts both together; the lag search absorbs what is left);
* per shape: Pearson r at lag 0 and at the best lag within +-300 ms (+ = facegen late), the 5th-95th
  percentile range of each and facegen / capture, the mean at rest (frames of silence, away from speech by
  REST_PAD_S), and the affine map `capture ~ scale * facegen + offset` that lays facegen's 5th-95th range
  onto the capture's: what the ARKit mapping would have to apply for a facegen weight to mean an iPhone's.

    python benchmarks/arkit_capture.py CAPTURE.csv AUDIO.wav [--text T | --text-file F] [--name NAME]
        [--model BUNDLE] [--facegen OUT.json] [--capture-fps N]

writes benchmarks/results/arkit_capture_NAME.json (NAME: the capture's file name without extension) and
prints the table of docs/arkit_capture.md. `--facegen` reuses an ARKit JSON/CSV facegen already wrote for the
audio instead of running it. Without a transcript facegen recognises the words itself (pocketsphinx).
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from real_faces_measures import best_of, lag_curve  # this folder, also when imported from elsewhere

from facegen.arkit.names import arkit_name
from facegen.audio import load_audio
from facegen.errors import FacegenError
from facegen.exchange.arkit_csv import parse_timecode

REPO = HERE.parent
RESULTS = HERE / "results"
MAX_LAG_S = 0.3  # best-lag search, either way
TARGETS = {"jawOpen_r": 0.75, "jawOpen_range_ratio": (0.7, 1.3)}  # issue 23
REST_BELOW_DB = 30.0  # a frame is loud within this many dB of the clip's 95th-percentile frame level
REST_PAD_S = 0.25  # rest: this far from any loud frame (the lips approach and leave rest around speech)
MIN_RANGE = 0.02  # a 5th-95th range under this is a shape that hardly moves: no scale is read from it
TIMECODE_RATES = (24, 25, 30, 48, 50, 60, 72, 90, 100, 120, 240)

# the shapes that say how the lips move in speech: the mapping's calibration reads these
MOUTH = ("jawOpen", "mouthClose", "mouthFunnel", "mouthPucker", "mouthSmileLeft", "mouthSmileRight",
         "mouthStretchLeft", "mouthStretchRight", "mouthLowerDownLeft", "mouthLowerDownRight",
         "mouthUpperUpLeft", "mouthUpperUpRight")
# for information: the rest of the mouth, the brows, eyes and cheeks
OTHER = ("jawForward", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
         "mouthPressLeft", "mouthPressRight", "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft",
         "mouthDimpleRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "browInnerUp",
         "browDownLeft", "browDownRight", "browOuterUpLeft", "browOuterUpRight", "eyeBlinkLeft",
         "eyeBlinkRight", "eyeSquintLeft", "eyeSquintRight", "eyeWideLeft", "eyeWideRight")


@dataclass
class Track:
    """ARKit weights [T, K] of `names` (ARKit's lowerCamel) at `times` (s from the first frame)."""

    names: tuple[str, ...]
    weights: np.ndarray
    times: np.ndarray

    @property
    def fps(self) -> float:
        return (len(self.times) - 1) / float(self.times[-1] - self.times[0]) if len(self.times) > 1 else 0.0

    def column(self, name: str) -> np.ndarray | None:
        return self.weights[:, self.names.index(name)] if name in self.names else None


# ------------------------------------------------------------------------------------------- reading
def timecode_rate(frames: list[int]) -> int:
    """The frame rate a Live Link Face CSV's Timecodes count in (their FF field runs 0..rate-1): the smallest
    common rate above the largest FF seen (right for any take of a second or more)."""
    top = max(frames, default=0) + 1
    return next((r for r in TIMECODE_RATES if r >= top), top)


def read_capture(path: str | Path, rate: float | None = None) -> Track:
    """A Live Link Face CSV's 52 shapes and their times (from the Timecodes HH:MM:SS:FF.mmm, FF counted at
    `rate`, else at timecode_rate's guess); columns named by arkit_name (any case, so the app's
    "BlendshapeCount" spelling too), head and eye rotations left out."""
    path = Path(path)
    with open(path, newline="", encoding="utf-8-sig") as f:
        header, *rows = [r for r in csv.reader(f) if r]
    if not rows:
        raise FacegenError(f"{path} has no frames: pass a Live Link Face CSV (a header, a row per frame)")
    lower = [c.strip().lower() for c in header]
    if "timecode" not in lower:
        raise FacegenError(f"{path} has no Timecode column: pass a Live Link Face CSV")
    shapes = [(i, arkit_name(c)) for i, c in enumerate(header) if arkit_name(c)]
    if not shapes:
        raise FacegenError(f"{path} has no ARKit shape columns (JawOpen, MouthClose, ...)")
    t_col = lower.index("timecode")
    parsed = [parse_timecode(r[t_col]) for r in rows]
    bad = next((k for k, p in enumerate(parsed) if p is None), None)
    if bad is not None:
        raise FacegenError(f"{path} row {bad + 1}: {rows[bad][t_col]!r} is not a timecode HH:MM:SS:FF[.mmm]")
    rate = rate or timecode_rate([p[1] for p in parsed])
    times = np.array([s + (f + sub) / rate for s, f, sub in parsed])
    if np.any(np.diff(times) <= 0):
        raise FacegenError(f"{path}: the Timecodes do not increase (is the frame rate {rate:g}? say so)")
    try:
        weights = np.array([[float(r[i]) for i, _ in shapes] for r in rows], np.float64)
    except (ValueError, IndexError) as exc:
        raise FacegenError(f"{path}: a weight is not a number or a row is short ({exc})") from None
    return Track(tuple(n for _, n in shapes), weights, times - times[0])


def read_facegen(path: str | Path) -> Track:
    """facegen's ARKit weights: its Audio2Face JSON (frame k at k / exportFps) or Live Link Face CSV."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        return read_capture(path)
    doc = json.loads(path.read_text())
    weights = np.asarray(doc["weightMat"], np.float64)
    return Track(tuple(doc["facsNames"]), weights, np.arange(len(weights)) / float(doc["exportFps"]))


def run_facegen(audio: Path, out: Path, text: str | None = None, text_file: Path | None = None,
                model: str | None = None) -> str:
    """`facegen animate AUDIO -o OUT` (ARKit JSON by its suffix), as a user runs it; returns what it said
    (the words it heard when it had no transcript). A failure is a FacegenError with facegen's message."""
    cmd = [sys.executable, "-m", "facegen", "animate", str(audio), "-o", str(out)]
    cmd += ["--text", text] if text else []
    cmd += ["--text-file", str(text_file)] if text_file else []
    cmd += ["--model", model] if model else []
    done = subprocess.run(cmd, check=False, capture_output=True, text=True)
    if done.returncode:
        raise FacegenError(f"facegen animate failed: {done.stderr.strip().splitlines()[-1:]}")
    return done.stderr


# ------------------------------------------------------------------------------------------- measures
def on_frames(track: Track, fps: float, n: int) -> np.ndarray:
    """`track`'s weights on n frames at `fps` (frame k at k / fps): each the mean of the track over about the
    frame's 1 / fps (a centred running mean of an odd number of samples: an even one would shift the track by
    half a sample), then linear interpolation; a 60 fps capture is not aliased."""
    width = 2 * round(track.fps / fps / 2) + 1 if track.fps else 1
    kernel = np.ones(width) / width
    out = np.empty((n, track.weights.shape[1]))
    t = np.arange(n) / fps
    for j in range(track.weights.shape[1]):
        x = track.weights[:, j]
        if width > 1:  # pad with the edge values, not zeros
            x = np.convolve(np.pad(x, (width // 2, width - 1 - width // 2), mode="edge"), kernel, "valid")
        out[:, j] = np.interp(t, track.times, x)
    return out


def frame_levels(samples: np.ndarray, sr: int, fps: float, n: int) -> np.ndarray:
    """RMS level (dB) of the audio around each of n frames at `fps` (frame k: [k - 1/2, k + 1/2] / fps)."""
    half = sr / fps / 2
    out = np.full(n, -200.0)
    for k in range(n):
        a, b = int(max(0, k * sr / fps - half)), int(min(len(samples), k * sr / fps + half))
        if b > a:
            out[k] = 10 * np.log10(float(np.mean(np.square(samples[a:b], dtype=np.float64))) + 1e-20)
    return out


def rest_frames(levels_db: np.ndarray, fps: float, below_db: float = REST_BELOW_DB,
                pad_s: float = REST_PAD_S) -> np.ndarray:
    """Frames of silence: quieter than the clip's 95th-percentile level less `below_db`, and `pad_s` or more
    from any louder frame (where the lips are still moving into or out of speech)."""
    loud = levels_db > np.percentile(levels_db, 95) - below_db
    pad = round(pad_s * fps)
    near = np.convolve(loud.astype(float), np.ones(2 * pad + 1), "same") > 0
    return ~near


def sound_lead_ms(weight: np.ndarray, levels_db: np.ndarray, fps: float, max_lag_s: float = MAX_LAG_S,
                  floor_db: float = 40.0) -> int | None:
    """How far (ms) a shape's motion runs ahead of the sound's level (floored `floor_db` under its peak): the
    best lag of the level against the weight, + = the shape moves first. Real lips lead the sound by some tens
    of ms; a capture whose jaw trails its audio is late against it (tracking latency, the audio's offset)."""
    env = np.maximum(levels_db, float(np.max(levels_db)) - floor_db)
    _, lag = best_of(lag_curve(env, weight, fps, max_lag_s))
    return None if lag is None else round(1000 * lag / fps)


def shape_stats(fg: np.ndarray, cap: np.ndarray, fps: float, rest: np.ndarray,
                max_lag_s: float = MAX_LAG_S) -> dict:
    """One shape, facegen `fg` against the capture `cap` (same frames): r at lag 0 and the best lag (frames
    and ms, + = facegen late), 5th-95th ranges and facegen / capture, the means at rest, and the affine map
    laying facegen's 5th-95th onto the capture's (capture ~ scale * facegen + offset; None where facegen
    hardly moves the shape)."""
    curve = lag_curve(fg, cap, fps, max_lag_s)
    r_best, lag = best_of(curve)
    p_fg, p_cap = np.percentile(fg, [5, 95]), np.percentile(cap, [5, 95])
    range_fg, range_cap = float(p_fg[1] - p_fg[0]), float(p_cap[1] - p_cap[0])
    scale = range_cap / range_fg if range_fg >= MIN_RANGE else None
    return {
        "r_lag0": curve.get(0),
        "r_best": r_best,
        "best_lag_frames": lag,
        "best_lag_ms": None if lag is None else round(1000 * lag / fps),
        "p5_p95_facegen": p_fg.round(4).tolist(),
        "p5_p95_capture": p_cap.round(4).tolist(),
        "range_facegen": round(range_fg, 4),
        "range_capture": round(range_cap, 4),
        "range_ratio": round(range_fg / range_cap, 3) if range_cap >= MIN_RANGE else None,
        "max_facegen": round(float(fg.max()), 4),
        "max_capture": round(float(cap.max()), 4),
        "rest_facegen": round(float(fg[rest].mean()), 4) if rest.any() else None,
        "rest_capture": round(float(cap[rest].mean()), 4) if rest.any() else None,
        "scale": None if scale is None else round(scale, 3),
        "offset": None if scale is None else round(float(p_cap[0] - scale * p_fg[0]), 4),
    }


def compare(fg: Track, cap: Track, samples: np.ndarray, sr: int, max_lag_s: float = MAX_LAG_S) -> dict:
    """Every shape both tracks have, on facegen's frames over the time both cover (see shape_stats)."""
    fps = round(fg.fps, 6)  # facegen's frames are evenly spaced: its exact rate, not a float's rounding of it
    n = min(len(fg.times), int(np.floor(cap.times[-1] * fps + 1e-9)) + 1)
    if n < 2 * round(max_lag_s * fps) + 10:
        raise FacegenError(f"the capture and facegen's animation overlap by {n} frames: too short to compare")
    on = on_frames(cap, fps, n)
    levels = frame_levels(samples, sr, fps, n)
    rest = rest_frames(levels, fps)
    shapes = {}
    for name in MOUTH + OTHER:
        if name in fg.names and name in cap.names:
            j = cap.names.index(name)
            shapes[name] = shape_stats(fg.column(name)[:n], on[:, j], fps, rest, max_lag_s)
    jaw = shapes.get("jawOpen", {})
    ratio = jaw.get("range_ratio")
    sync = {}
    if "jawOpen" in shapes:  # each jaw against the sound: is the capture in step with its audio?
        for who, x in (("capture", on[:, cap.names.index("jawOpen")]), ("facegen", fg.column("jawOpen")[:n])):
            sync[f"{who}_jaw_lead_ms"] = sound_lead_ms(x, levels, fps, max_lag_s)
    return {
        "fps": fps,
        "frames": n,
        "seconds": round(n / fps, 2),
        "rest_frames": int(rest.sum()),
        "capture_fps": round(cap.fps, 3),
        "max_lag_s": max_lag_s,
        "sync": sync,
        "shapes": shapes,
        "targets": {
            "jawOpen_r_lag0": jaw.get("r_lag0"),
            "jawOpen_r_best": jaw.get("r_best"),
            "jawOpen_range_ratio": ratio,
            "r_met_lag0": None if jaw.get("r_lag0") is None else jaw["r_lag0"] >= TARGETS["jawOpen_r"],
            "range_met": None if ratio is None else (TARGETS["jawOpen_range_ratio"][0] <= ratio
                                                     <= TARGETS["jawOpen_range_ratio"][1]),
        },
    }


# ------------------------------------------------------------------------------------------- report
def _f(x, digits: int = 2) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def table(result: dict) -> str:
    """The Markdown table of docs/arkit_capture.md: one row per shape, the mouth first."""
    head = ("| shape | r lag 0 | r best (lag ms) | p5-p95 facegen | p5-p95 capture | range ratio fg/cap | "
            "rest fg / cap | scale, offset to match |\n|---|---|---|---|---|---|---|---|")
    lines = [head]
    for name, s in result["shapes"].items():
        if name == OTHER[0]:
            lines.append("| *for information* | | | | | | | |")
        lo_f, hi_f = s["p5_p95_facegen"]
        lo_c, hi_c = s["p5_p95_capture"]
        match = "-" if s["scale"] is None else f"x{s['scale']:.2f} {s['offset']:+.2f}"
        lines.append(f"| {name} | {_f(s['r_lag0'])} | {_f(s['r_best'])} ({s['best_lag_ms']}) | "
                     f"{lo_f:.2f}-{hi_f:.2f} | {lo_c:.2f}-{hi_c:.2f} | {_f(s['range_ratio'])} | "
                     f"{_f(s['rest_facegen'])} / {_f(s['rest_capture'])} | {match} |")
    return "\n".join(lines)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run(capture: Path, audio: Path, *, text: str | None = None, text_file: Path | None = None,
        model: str | None = None, facegen: Path | None = None, capture_fps: float | None = None) -> dict:
    """The whole benchmark for one capture: facegen on its audio (or `facegen`'s file), compared."""
    cap = read_capture(capture, capture_fps)
    said = ""
    with tempfile.TemporaryDirectory() as tmp:
        if facegen is None:
            facegen = Path(tmp) / "facegen.json"
            said = run_facegen(audio, facegen, text, text_file, model)
        fg = read_facegen(facegen)
    samples, sr = load_audio(audio)
    result = compare(fg, cap, samples, sr)
    heard = [line.split("heard:", 1)[1].strip() for line in said.splitlines() if "heard:" in line]
    result.update({
        "capture": {"file": capture.name, "sha256": _sha256(capture), "frames": len(cap.times),
                    "seconds": round(float(cap.times[-1]), 3)},
        "audio": {"file": audio.name, "sha256": _sha256(audio), "seconds": round(len(samples) / sr, 3)},
        "transcript": text or (text_file.read_text().strip() if text_file else None),
        "heard": heard[0] if heard else None,
        "model": model or "default",
    })
    return result


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", type=Path, help="Live Link Face CSV of the take")
    ap.add_argument("audio", type=Path, help="the take's audio (WAV, FLAC, OGG, MP3), starting with the CSV")
    ap.add_argument("--text", help="the transcript (else facegen recognises the words)")
    ap.add_argument("--text-file", type=Path, help="a UTF-8 file with the transcript")
    ap.add_argument("--model", help="model bundle (default: the built-in model)")
    ap.add_argument("--facegen", type=Path, help="facegen's ARKit JSON/CSV for the audio, already written")
    ap.add_argument("--capture-fps", type=float, help="the rate the CSV's Timecode frames count in "
                                                      "(default: guessed from them)")
    ap.add_argument("--name", help="results name (default: the capture's file name)")
    args = ap.parse_args(argv)
    try:
        result = run(args.capture, args.audio, text=args.text, text_file=args.text_file, model=args.model,
                     facegen=args.facegen, capture_fps=args.capture_fps)
    except FacegenError as exc:  # one line, exit 2, no partial output (the project's rule for user errors)
        print(f"arkit_capture: {exc}", file=sys.stderr)
        sys.exit(2)
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = RESULTS / f"arkit_capture_{args.name or args.capture.stem}.json"
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    t = result["targets"]
    low, high = TARGETS["jawOpen_range_ratio"]
    print(f"\njawOpen: r {_f(t['jawOpen_r_lag0'])} at lag 0, {_f(t['jawOpen_r_best'])} at best; range "
          f"facegen/capture {_f(t['jawOpen_range_ratio'])} (targets r >= {TARGETS['jawOpen_r']}, range "
          f"{low}-{high}); {result['rest_frames']} rest frames; jaw before the sound by "
          f"{result['sync'].get('capture_jaw_lead_ms')} ms (capture), "
          f"{result['sync'].get('facegen_jaw_lead_ms')} ms (facegen); "
          f"{out.relative_to(REPO) if out.is_relative_to(REPO) else out}")


if __name__ == "__main__":
    main()
