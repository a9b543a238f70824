"""Real faces: facegen's lips against people's, both seen by one tracker (issue 23).

Each real clip (GRID corpus samples in benchmarks/data/grid/: read sentences, video with its audio) is
tracked with MediaPipe Face Mesh; facegen animates the clip's audio with its transcript, the animation is
rendered front on (512 px) and tracked the same way. Both faces are then measured alike (real_faces_measures:
inner-lip aperture 13-14, mouth width 61-291, jaw nose-to-chin, in cm on the iris scale):

* aperture r, facegen vs real, at lag 0 and at the best lag within +-200 ms (+ = facegen late), over the
  whole clip and over its speech (first word - 200 ms to last word + 200 ms);
* the median aperture ratio facegen / real over the open speech frames (real aperture > 0.2 cm), and p95;
* p/b/m closure seen by the tracker: the share of p/b/m midpoints (pocketsphinx's phone alignment of the
  transcript, the one facegen animates from) with the lips under 0.1 cm, real and facegen;
* opening per vowel (viseme) and class, range (5th-95th percentile) of aperture and width;
* for the rig's calibration: closure durations and their timing against the phones, how far the lips lead the
  sound (envelope cross-correlation, utterance onsets), width of spread vs rounded vowels.

MediaPipe (mediapipe==0.10.14, whose wheel ships the face models) lives in its own venv, `make faces-venv`:
the tracker runs there (benchmarks/real_faces_track.py), everything else here in facegen's venv.

    python benchmarks/real_faces.py [--model BUNDLE] [--name NAME] [--clips N] [--lit-cavity]

writes benchmarks/results/real_faces_NAME.json (NAME: the bundle's file name without extension) and prints
the table of docs/real_faces.md. Importable: `run(...)` returns the same dict.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from real_faces_measures import (
    CLOSED_CM,
    OPEN_CM,
    best_of,
    closure_rate,
    closures,
    envelope_curve,
    envelope_lead,
    lag_curve,
    median_ratio,
    onset_lead,
    rest_width,
    speech_span,
    tracks_of,
    vowel_values,
)
from real_faces_report import summarize, table  # this folder, also when imported from elsewhere

REPO = HERE.parent
DATA = HERE / "data" / "grid"
RESULTS = HERE / "results"
TRACKER = HERE / "real_faces_track.py"
FACES_VENV = REPO / ".venv-faces"
SIZE = 512  # px, the render (the front view only)

# GRID's file names spell the sentence: command, colour, preposition, letter, digit, adverb
_GRID = (
    {"b": "bin", "l": "lay", "p": "place", "s": "set"},
    {"b": "blue", "g": "green", "r": "red", "w": "white"},
    {"a": "at", "b": "by", "i": "in", "w": "with"},
    None,
    {
        "z": "zero",
        "1": "one",
        "2": "two",
        "3": "three",
        "4": "four",
        "5": "five",
        "6": "six",
        "7": "seven",
        "8": "eight",
        "9": "nine",
    },
    {"a": "again", "n": "now", "p": "please", "s": "soon"},
)


def grid_transcript(name: str) -> str:
    """The sentence of a GRID clip from its file name (the last 6 characters of the stem, e.g. 'bbaf2n' →
    'bin blue at f two now'); the letter is said as the letter."""
    code = Path(name).stem[-6:].lower()
    if len(code) != 6:
        raise ValueError(f"not a GRID clip name: {name}")
    return " ".join(code[i] if table is None else table[code[i]] for i, table in enumerate(_GRID))


def read_grid_align(path: Path) -> list[tuple[str, float, float]]:
    """GRID's own word alignment (`start end word` per line, in 1/25000 s: 1000 per 25 fps video frame),
    silences left out."""
    words = []
    for line in path.read_text().split("\n"):
        if line.strip():
            start, end, word = line.split()
            if word != "sil":
                words.append((word, int(start) / 25000, int(end) / 25000))
    return words


def alignment_error(ours: list, grid: list) -> float | None:
    """Mean |difference| (s) of the word starts and ends of two alignments of the same words, else None."""
    if [w[0] for w in ours] != [w[0] for w in grid]:
        return None
    return float(np.mean([abs(a[i] - b[i]) for a, b in zip(ours, grid, strict=True) for i in (1, 2)]))


def faces_python() -> Path:
    """The faces venv's Python (MediaPipe); FACEGEN_FACES_PYTHON overrides it."""
    path = Path(os.environ.get("FACEGEN_FACES_PYTHON", FACES_VENV / "bin" / "python"))
    if not path.exists():
        raise SystemExit(
            f"no MediaPipe venv at {path}: run `make faces-venv` (mediapipe==0.10.14 in .venv-faces)"
        )
    return path


def track(inputs: list[Path], out: Path) -> list[np.ndarray]:
    """Landmarks [T, 478, 3] (pixels) of each input (a video, or a .npy of RGB frames), in one tracker run."""
    proc = subprocess.run(
        [str(faces_python()), str(TRACKER), str(out), *map(str, inputs)],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        raise SystemExit(f"the tracker failed: {proc.stderr[-2000:]}")
    with np.load(out) as found:
        return [found[f"lm{k}"] for k in range(len(inputs))]


def extract_audio(video: Path, wav: Path) -> None:
    from facegen.processes import run_tool

    proc = run_tool("ffmpeg", ["-v", "error", "-y", "-i", video, "-vn", "-ac", "1", wav])
    if proc.returncode != 0:
        raise SystemExit(f"ffmpeg could not read the audio of {video}: {proc.stderr[-500:]!r}")


def render_frames(anim, out: Path, lit_cavity: bool) -> None:
    """The animation's front view, RGB [T, SIZE, SIZE, 3] uint8, into the .npy `out` (no video codec between
    the render and the tracker), drawn as `facegen render` draws it: the face and its parts (eyes, teeth,
    tongue), the mouth's inside in shadow (render.scene.CAVITY_SHADE). `lit_cavity`: the cavity lit, as
    releases before 2026-12-07 drew it (the tracker then takes it for lip and misses small openings)."""
    from facegen.render.raster import Renderer
    from facegen.render.scene import CAVITY_SHADE, Scene

    scene = Scene(anim, parts=True)
    renderer = Renderer(scene.faces, scene.template, SIZE, ("front",))
    colors = scene.colors
    if lit_cavity and colors is not None and "mouth_cavity" in anim.regions:
        colors = colors.copy()
        colors[np.asarray(anim.regions["mouth_cavity"])] /= CAVITY_SHADE
    frames = np.lib.format.open_memmap(out, "w+", np.uint8, (anim.num_frames, SIZE, SIZE, 3))
    for t in range(anim.num_frames):
        renderer.render_into(scene.points(np.asarray(anim.vertices[t]), t), frames[t], colors)
    frames.flush()
    del frames


def _round(x, nd=4):
    """x for JSON: arrays as lists, floats to `nd` decimals."""
    if isinstance(x, dict):
        return {k: _round(v, nd) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_round(v, nd) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return round(float(x), nd)
    return x


def _pct(x: np.ndarray) -> list[float]:
    return [float(np.percentile(x, 5)), float(np.percentile(x, 95))]


def measure_clip(real, fg, geo, words, phones, loudness, fps, geo_width=None) -> dict:
    """The per-clip numbers: `real` and `fg` are Tracks of the same length, `geo` facegen's geometric aperture
    (cm, facegen.lipsync.aperture), `geo_width` its geometric mouth width's change from the neutral face (cm,
    facegen.lipsync.mouth_width; the tracker misreads facegen's width). facegen's timing (closures, leads) is
    read off `geo`: the tracker does not see facegen's openings under ~0.45 cm (`response_curve`), so its
    closures would last through them."""
    from facegen.lipsync import bilabial_midpoints, lagged_r, speech_mask

    n = len(real)
    geo = np.asarray(geo, np.float64)[:n]
    talking = speech_mask(words, n, fps)
    is_open = talking & (real.aperture > OPEN_CM)
    mids = bilabial_midpoints(phones, fps, alphabet="cmu")
    sp = np.flatnonzero(speech_span(words, n, fps))
    a, b = (sp[0], sp[-1] + 1) if len(sp) else (0, n)
    curve = lag_curve(fg.aperture, real.aperture, fps)
    curve_speech = lag_curve(fg.aperture[a:b], real.aperture[a:b], fps)
    out: dict = {
        "frames": n,
        "tracked_real": real.found,
        "tracked_facegen": fg.found,
        "iris_px_real": real.iris_px,
        "iris_px_facegen": fg.iris_px,
        "aperture_r": curve.get(0),
        "aperture_r_speech": curve_speech.get(0),
        "aperture_r_geometric": lagged_r(geo, real.aperture, 0),
    }
    for key, c in (("", curve), ("_speech", curve_speech)):
        r, lag = best_of(c)
        out[f"aperture_best_r{key}"], out[f"aperture_best_lag{key}_s"] = r, None if lag is None else lag / fps
    out["open_frames"] = int(is_open.sum())
    out["median_ratio"] = median_ratio(fg.aperture, real.aperture, is_open)
    out["median_ratio_geometric"] = median_ratio(geo, real.aperture, is_open)
    out["p95_ratio"] = (
        float(np.percentile(fg.aperture[is_open], 95) / np.percentile(real.aperture[is_open], 95))
        if is_open.any()
        else None
    )
    out["bilabials"] = len(mids)
    series = {"real": real.aperture, "facegen": fg.aperture, "facegen_geometric": geo}
    for who, ap in series.items():
        out[f"closure_rate_{who}"] = closure_rate(ap, mids)
        out[f"closure_rate_1frame_{who}"] = closure_rate(ap, mids, reach=1)
        out[f"aperture_range_{who}_cm"] = _pct(ap)
    for who, ap in (("real", real.aperture), ("facegen_geometric", geo)):
        out[f"envelope_lead_{who}_s"], out[f"envelope_r_{who}"] = envelope_lead(ap, fps, loudness)
        rest = float(np.median(ap[~talking])) if (~talking).any() else 0.0  # facegen rests at ~0.1 cm
        out[f"onset_lead_{who}_s"] = onset_lead(ap, words, phones, fps, closed=max(rest, 0.0) + CLOSED_CM)
        out[f"closures_{who}"] = closures(ap, phones, fps)
    for who, tr in (("real", real), ("facegen", fg)):
        out[f"width_range_{who}_cm"] = _pct(tr.width)
        out[f"jaw_p95_{who}_cm"] = float(np.percentile(tr.jaw, 95))
        out[f"rest_width_{who}_cm"] = w0 = rest_width(tr, talking)
        ap = geo if who == "facegen" else tr.aperture  # relative opening: over the clip's 95th percentile
        extra = {"aperture_rel": ap / max(np.percentile(ap, 95), 1e-6)}
        mine = {"geometric": geo} | ({} if geo_width is None else {"geometric_width_change": geo_width[:n]})
        out[f"vowels_{who}"] = vowel_values(tr, phones, fps, w0, extra | (mine if who == "facegen" else {}))
    out["facegen_tracked_vs_geometric_r"] = lagged_r(fg.aperture, geo, 0)
    out["facegen_tracked_over_geometric"] = median_ratio(fg.aperture, geo, geo > OPEN_CM)
    out["tracks"] = {
        "real": {"aperture": real.aperture, "width": real.width, "jaw": real.jaw},
        "facegen": {"aperture": fg.aperture, "width": fg.width, "jaw": fg.jaw, "geometric_aperture": geo},
    }
    # for the summary only (dropped before writing): lag curves and the open frames
    out["_curves"] = {
        "aperture": curve,
        "aperture_speech": curve_speech,
        "envelope_real": envelope_curve(real.aperture, fps, loudness),
        "envelope_facegen_geometric": envelope_curve(geo, fps, loudness),
    }
    out["_open"] = is_open
    return out


def run(
    model=None,
    *,
    data: Path = DATA,
    clips: int | None = None,
    lit_cavity: bool = False,
    speaker=None,
    log=print,
) -> dict:
    """Measure `model` (a bundle path or None: the built-in model) on the clips in `data`; the result dict."""
    import facegen
    from facegen.align import align_phones
    from facegen.audio import load_audio
    from facegen.lipsync import FaceGeometry, mouth_width
    from facegen.lipsync import aperture as geometric_aperture
    from facegen.synth.curves import loudness_envelope

    videos = sorted(data.glob("*.mpg"))[:clips]
    if not videos:
        raise SystemExit(f"no GRID clips (*.mpg) in {data}")
    start = time.perf_counter()
    animator = facegen.Animator(model)
    face = FaceGeometry.of(animator.mesh())  # facegen's geometric aperture, for the tracker check
    neutral_width = float(mouth_width(face.template[None], face)[0])
    per_clip: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        made = []
        for video in videos:
            name, text = video.stem, grid_transcript(video.stem)
            wav = tmp / f"{name}.wav"
            extract_audio(video, wav)
            audio, sr = load_audio(wav)
            words, phones = align_phones(audio, sr, text)
            # the lips alone: no blinks (MediaPipe's iris landmarks, the scale, go astray under a shut lid)
            # and no head motion (the render does not turn the head; the tracker's scale would follow it)
            anim = animator.animate(wav, text=text, speaker=speaker, blink_rate=0, head_motion=0)
            frames = tmp / f"{name}_facegen.npy"
            render_frames(anim, frames, lit_cavity)
            geo = geometric_aperture(np.asarray(anim.vertices), face)
            geo_width = mouth_width(np.asarray(anim.vertices), face) - neutral_width
            made.append(
                (
                    name,
                    text,
                    video,
                    frames,
                    [(w.text, w.start, w.end) for w in words],
                    phones,
                    loudness_envelope(audio, sr),
                    geo,
                    float(anim.fps),
                    geo_width,
                )
            )
            log(f"  {name}: animated and rendered ({time.perf_counter() - start:.0f} s)")
        tracked = track([p for m in made for p in (m[2], m[3])], tmp / "landmarks.npz")
        log(f"  tracked {len(tracked)} videos ({time.perf_counter() - start:.0f} s)")
    for k, (name, text, _, _, words, phones, loudness, geo, fps, geo_width) in enumerate(made):
        real, fg = tracks_of(tracked[2 * k]), tracks_of(tracked[2 * k + 1])
        n = min(len(real), len(fg))
        row = measure_clip(real.cut(n), fg.cut(n), geo, words, phones, loudness, fps, geo_width)
        row.update(transcript=text, words=words, phones=phones)
        grid = data / f"{name[-6:]}.align"
        if grid.exists():  # GRID's own word times: how far pocketsphinx's are from them
            row["grid_alignment"] = read_grid_align(grid)
            row["alignment_vs_grid_s"] = alignment_error(words, row["grid_alignment"])
        per_clip[name] = row
    summary = summarize(per_clip)
    for row in per_clip.values():
        del row["_open"], row["_curves"]
    return _round(
        {
            "model": str(model or "built-in (facegen/models/default.safetensors)"),
            "render": "face and parts, cavity " + ("lit" if lit_cavity else "in shadow"),
            "closed_cm": CLOSED_CM,
            "open_cm": OPEN_CM,
            "seconds": time.perf_counter() - start,
            "summary": summary,
            "clips": per_clip,
        }
    )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", help="model bundle (default: the built-in model)")
    ap.add_argument(
        "--name",
        help="results name: benchmarks/results/real_faces_NAME.json (default: the "
        "bundle's file name, 'default' for the built-in model)",
    )
    ap.add_argument("--data", type=Path, default=DATA, help="folder of GRID clips (*.mpg)")
    ap.add_argument("--clips", type=int, help="measure only the first N clips")
    ap.add_argument("--speaker", help="the model's speaker (default: the model's default)")
    ap.add_argument(
        "--lit-cavity",
        action="store_true",
        help="draw the mouth cavity lit, as releases before 2026-12-07 did (the tracker misses openings)",
    )
    args = ap.parse_args(argv)
    name = args.name or (Path(args.model).stem if args.model else "default")
    result = run(
        args.model, data=args.data, clips=args.clips, lit_cavity=args.lit_cavity, speaker=args.speaker
    )
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = RESULTS / f"real_faces_{name}.json"
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    print(f"\n{out.relative_to(REPO) if out.is_relative_to(REPO) else out}: {result['seconds']:.0f} s")


if __name__ == "__main__":
    main()
