"""How far the lips follow a word's loudness, against the rig's prosody rule (issue 23).

Real speech grows quieter toward a phrase's end; a model trained on synthetic voices, which hold their level,
can read a quiet final word as a shut mouth. This benchmark takes the real GRID clips (benchmarks/data/grid/:
read sentences, each ending in "now", "again", "please" or "soon"), makes the final word 6 dB quieter and
6 dB louder (a gain over the word's aligned span, 30 ms ramps), and animates each version with its
transcript. Per clip and version it measures the final word's peak lip aperture (facegen.lipsync.aperture,
cm) by the model and by facegen's rig driven by the same phones and the same audio's loudness
(facegen.synth.curves: louder vowels open up to PROSODY_GAIN wider over PROSODY_DB; the training motion's
rule). Reported, as medians over the clips:

* **final word, model / rig** at the clip's own level: how wide the model opens a real speaker's final word
  where its teacher opens it (1.0: as wide);
* **response to -6 dB and +6 dB**: the final word's peak over its peak at 0 dB, the model's and the rig's
  (the rig: about 0.83 and 1.17 where its rule is not clipped). A model far below the rig at -6 dB closes
  the mouth on quiet syllables beyond what the motion it learnt says.

    python benchmarks/loudness_response.py [--model BUNDLE] [--name NAME] [--clips N]

writes benchmarks/results/loudness_response_NAME.json and prints the table. Needs ffmpeg (the clips' audio)
and nothing of MediaPipe.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from real_faces import DATA, extract_audio, grid_transcript  # this folder

RESULTS = HERE / "results"
GAINS_DB = (-6.0, 0.0, 6.0)
RAMP_S = 0.03


def word_gain(audio: np.ndarray, sr: int, start: float, end: float, db: float) -> np.ndarray:
    """`audio` with `db` of gain over [start, end] s, ramped in and out over RAMP_S (no click)."""
    t = np.arange(len(audio)) / sr
    inside = np.clip(np.minimum(t - start + RAMP_S, end + RAMP_S - t) / RAMP_S, 0.0, 1.0)
    return np.clip(audio * 10.0 ** (db * inside / 20.0), -1.0, 1.0).astype(np.float32)


def _peak(curve: np.ndarray, start: float, end: float, fps: float) -> float:
    a, b = int(np.floor(start * fps)), int(np.ceil(end * fps)) + 1
    return float(np.max(curve[max(a, 0): max(b, a + 1)]))


def run(model=None, *, data: Path = DATA, clips: int | None = None, log=print) -> dict:
    import facegen
    from facegen.align import align_phones
    from facegen.audio import load_audio, write_wav
    from facegen.lipsync import FaceGeometry, aperture
    from facegen.synth.corpus import speaker_index
    from facegen.synth.curves import SpeakerStyle, formant_track, loudness_envelope
    from facegen.synth.reference import rig_reference

    videos = sorted(data.glob("*.mpg"))[:clips]
    if not videos:
        raise SystemExit(f"no GRID clips (*.mpg) in {data}")
    start_time = time.perf_counter()
    animator = facegen.Animator(model)
    face = FaceGeometry.of(animator.mesh())
    speaker = animator.bundle.speakers[0]
    style = SpeakerStyle.for_speaker(speaker_index(speaker))  # the rig moves as the model's speaker
    per_clip = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for video in videos:
            name, text = video.stem, grid_transcript(video.stem)
            wav = tmp / f"{name}.wav"
            extract_audio(video, wav)
            audio, sr = load_audio(wav)
            words, phones = align_phones(audio, sr, text)
            last = words[-1]
            row = {"transcript": text, "final_word": [last.text, last.start, last.end]}
            for db in GAINS_DB:
                louder = word_gain(audio, sr, last.start, last.end, db)
                path = tmp / f"{name}_{db:+.0f}.wav"
                write_wav(louder, sr, path)
                anim = animator.animate(path, text=text, blink_rate=0, head_motion=0)
                model_ap = aperture(np.asarray(anim.vertices), face)
                rig_ap = aperture(rig_reference(phones, [], anim.num_frames, float(anim.fps), alphabet="cmu",
                                                loudness=loudness_envelope(louder, sr),
                                                f1=formant_track(louder, sr), style=style), face)
                row[f"{db:+.0f}dB"] = {"model_cm": _peak(model_ap, last.start, last.end, float(anim.fps)),
                                       "rig_cm": _peak(rig_ap, last.start, last.end, float(anim.fps))}
            base = row["+0dB"]
            row["model_over_rig"] = base["model_cm"] / max(base["rig_cm"], 1e-6)
            for db in ("-6dB", "+6dB"):
                row[f"model_response_{db}"] = row[db]["model_cm"] / max(base["model_cm"], 1e-6)
                row[f"rig_response_{db}"] = row[db]["rig_cm"] / max(base["rig_cm"], 1e-6)
            per_clip[name] = row
            log(f"  {name} ({last.text}): model/rig {row['model_over_rig']:.2f}, -6 dB model "
                f"{row['model_response_-6dB']:.2f} rig {row['rig_response_-6dB']:.2f}, +6 dB model "
                f"{row['model_response_+6dB']:.2f} rig {row['rig_response_+6dB']:.2f}")
    keys = ("model_over_rig", "model_response_-6dB", "rig_response_-6dB", "model_response_+6dB",
            "rig_response_+6dB")
    summary = {k: round(float(np.median([r[k] for r in per_clip.values()])), 3) for k in keys}
    return {"model": str(model or "built-in (facegen/models/default.safetensors)"), "speaker": speaker,
            "seconds": round(time.perf_counter() - start_time, 1), "summary": summary, "clips": per_clip}


def table(result: dict) -> str:
    s = result["summary"]
    return "\n".join([
        "| final word, median over clips | model | rig |",
        "|---|---|---|",
        f"| peak aperture, model / rig | {s['model_over_rig']:.2f} | 1 |",
        f"| at -6 dB / at 0 dB | {s['model_response_-6dB']:.2f} | {s['rig_response_-6dB']:.2f} |",
        f"| at +6 dB / at 0 dB | {s['model_response_+6dB']:.2f} | {s['rig_response_+6dB']:.2f} |",
    ])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", help="model bundle (default: the built-in model)")
    ap.add_argument("--name", help="results name (default: the bundle's file name, or 'default')")
    ap.add_argument("--data", type=Path, default=DATA, help="folder of GRID clips (*.mpg)")
    ap.add_argument("--clips", type=int, help="only the first N clips")
    args = ap.parse_args(argv)
    name = args.name or (Path(args.model).stem if args.model else "default")
    result = run(args.model, data=args.data, clips=args.clips)
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = RESULTS / f"loudness_response_{name}.json"
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    print(f"\n{out}: {result['seconds']:.0f} s")


if __name__ == "__main__":
    main()
