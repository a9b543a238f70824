"""Benchmark: 60 s of face animation (1500 frames at 25 fps, 23,370 vertices, 16 kHz audio) written as .glb.

Targets (issue 4): the .glb is <= 5 MB at the default tolerance (largest vertex error 1e-3 of the face
size) and is written in <= 3 s on 2 CPU cores. The animation is the procedural face (templates/) driven
by its rig from random phones (lips, jaw, lids, brows; facegen.synth), with a noise-burst sound; or any
[T, 3V] .npy with `--npy FILE --template MESH`. Prints per run: wall seconds, file bytes, K, the error;
and the MP3 encoder delay that was compensated. The Khronos validator runs once on the result when
Node and `make node-deps` are there.

    python benchmarks/bench_export.py [--seconds 60] [--runs 3] [--tolerance 1e-3] [--npy F --template M]

Long-clip memory case (issue 13): `--usd-long MINUTES [--usd-clips auto|never|N]` writes MINUTES of frames on
the default model's face (23,370 vertices) as a points .usdc from a FrameStream (the default model's output
layer over smooth random decoder states: no audio runs through the network), then validates it, and prints
the peak resident memory (VmHWM) after each step. Run it once per `--usd-clips` value, each in a new process:
`never` is the one-file layer (the writer before value clips), `auto` the value clips.

Write speed of points USD (`--usdc-throughput [--runs N]`): a minute (1500 frames at 25 fps) on the BIWI
template's 23,370 vertices (random ones without the dataset) written as .usdc, and the same frames as .npy
(the same bytes, raw: the I/O floor); prints frames/s of each (tests/test_exchange_usd.py checks the values).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def animation(args):
    if args.npy:
        from facegen.exchange import read_animation
        from facegen.face.mesh import read_mesh

        anim = read_animation(args.npy, template=read_mesh(args.template), fps=args.fps)
        if anim.audio is None:
            rng = np.random.default_rng(0)
            anim.audio = (0.1 * rng.standard_normal(int(anim.duration * 16000))).astype(np.float32)
        return anim, f"{args.npy}"
    from helpers import rig_clip

    return rig_clip(round(args.seconds * args.fps), fps=args.fps), "procedural face + rig, random phones"


def long_clip(minutes: float):
    """A FrameStream animation of `minutes` on the default model's face: its output layer over smooth random
    decoder states (LSTM-like values in -1..1), with a quiet noise track as long as the frames."""
    from facegen.animation import Animation
    from facegen.bundle import load_bundle
    from facegen.inference import frame_stream

    bundle = load_bundle()
    fps = bundle.features.fps
    frames = round(minutes * 60 * fps)
    rng = np.random.default_rng(0)
    width = bundle.model.fc_out.weight.shape[1]
    states = np.tanh(np.cumsum(0.05 * rng.standard_normal((frames, width)), axis=0)).astype(np.float32)
    face = bundle.template
    audio = (0.01 * rng.standard_normal(round(frames / fps * 16000))).astype(np.float32)
    return Animation(frame_stream(bundle, states, face.vertices), face.faces, fps, face.vertices, audio,
                     16000)


def usd_long(minutes: float, clips: str | None) -> None:
    """Write and validate a long points .usdc; print seconds, bytes and peak RSS after each step. `clips`
    None: the writer's default (and no `clips` option: runs on facegen versions before value clips too)."""
    from facegen.exchange import write_animation
    from facegen.runtime import peak_rss_mb
    from facegen.validate import validate

    t0 = time.perf_counter()
    anim = long_clip(minutes)
    made = peak_rss_mb()
    print(f"animation: {anim.num_frames} frames x {anim.num_vertices} vertices (a FrameStream), "
          f"made in {time.perf_counter() - t0:.1f} s; peak RSS {made:.0f} MB", flush=True)
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as folder:
        out = Path(folder) / "long.usdc"
        start = time.perf_counter()
        options = {} if clips is None else {"clips": int(clips) if clips.isdigit() else clips}
        files = write_animation(anim, out, **options)
        written, wrote = time.perf_counter() - start, peak_rss_mb()
        size = sum(f.stat().st_size for f in files)
        print(f"write (--usd-clips {clips}): {written:.1f} s, {len(files)} files, {size / 1e9:.2f} GB; "
              f"peak RSS {wrote:.0f} MB", flush=True)
        start = time.perf_counter()
        report = validate(out)
        checked, validated = time.perf_counter() - start, peak_rss_mb()
        print(f"validate: {'OK' if report.ok else 'FAILED'} in {checked:.1f} s; peak RSS {validated:.0f} MB")
        if not report.ok:
            print(report.to_text())
    print(json.dumps({"benchmark": "usd_long", "clips": clips, "frames": anim.num_frames,
                      "vertices": anim.num_vertices, "files": len(files), "bytes": size,
                      "write_seconds": round(written, 1), "peak_rss_mb_animation": round(made),
                      "peak_rss_mb_write": round(wrote), "validate_seconds": round(checked, 1),
                      "peak_rss_mb_validate": round(validated), "valid": report.ok,
                      "memory_ok": wrote <= 2048}))


def usdc_throughput(runs: int) -> None:
    """Time writing a minute of points as .usdc and as .npy; print frames/s (best of `runs`) and the size."""
    from facegen.animation import Animation
    from facegen.exchange import write_animation
    from facegen.face.mesh import Mesh, read_mesh

    ply = Path(__file__).resolve().parents[2] / "shared" / "biwi" / "BIWI.ply"
    if ply.is_file():
        mesh = read_mesh(ply)
    else:  # no BIWI template here: a random face of the same size
        rng = np.random.default_rng(0)
        mesh = Mesh(rng.standard_normal((23370, 3)).astype(np.float32),
                    rng.integers(0, 23370, (46068, 3)).astype(np.int32))
    frames, fps, rate = 1500, 25, 16000
    rng = np.random.default_rng(1)
    noise = (0.002 * rng.standard_normal((frames, 1, 3))).astype(np.float32)
    anim = Animation(mesh.vertices[None] + noise + 0.001 * np.arange(frames, dtype=np.float32)[:, None, None],
                     mesh.faces, fps, mesh.vertices, np.zeros(frames * rate // fps, np.float32), rate)
    best: dict[str, float] = {}
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as folder:
        for run in range(runs):
            for name, options in ((".usdc", {}), (".npy", {"write_audio": False})):
                out = Path(folder) / f"long{name}"
                start = time.perf_counter()
                write_animation(anim, out, **options)
                seconds = time.perf_counter() - start
                best[name] = min(best.get(name, seconds), seconds)
                size = out.stat().st_size
                out.unlink()
                print(f"run {run}: {name} {frames} frames x {mesh.num_vertices} vertices in {seconds:.2f} s "
                      f"= {frames / seconds:.0f} frames/s ({size / 1e6:.0f} MB)", flush=True)
    print(json.dumps({"benchmark": "usdc_throughput", "frames": frames, "vertices": mesh.num_vertices,
                      "usdc_frames_per_second": round(frames / best[".usdc"]),
                      "npy_frames_per_second": round(frames / best[".npy"])}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fps", type=float, default=25.0)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--tolerance", type=float, default=None, help="default: facegen's (1e-3)")
    parser.add_argument("--morph-targets", default=None, help="K or all (default: from the tolerance)")
    parser.add_argument("--npy", help="a [T, 3V] animation to write instead of the rig clip")
    parser.add_argument("--template", help="the template mesh of --npy")
    parser.add_argument("--usd-long", type=float, metavar="MINUTES", help="the long-clip USD memory case")
    parser.add_argument("--usd-clips", help="with --usd-long: auto, never or frames per clip (default: the "
                                            "writer's)")
    parser.add_argument("--usdc-throughput", action="store_true",
                        help="time a minute of points .usdc vs .npy")
    args = parser.parse_args()
    if args.usdc_throughput:
        usdc_throughput(args.runs)
        return
    if args.usd_long:
        usd_long(args.usd_long, args.usd_clips)
        return

    from facegen.exchange import gltf, write_animation
    from facegen.exchange.pca import DEFAULT_TOLERANCE, parse_morph_targets
    from facegen.validate.gltf import run_gltf_validator

    t0 = time.perf_counter()
    anim, source = animation(args)
    print(f"animation: {anim.num_frames} frames x {anim.num_vertices} vertices at {anim.fps:g} fps, "
          f"{anim.duration:.1f} s ({source}); made in {time.perf_counter() - t0:.1f} s", flush=True)
    tolerance = args.tolerance if args.tolerance is not None else DEFAULT_TOLERANCE
    options = {"tolerance": tolerance, "morph_targets": parse_morph_targets(args.morph_targets)}
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "minute.glb"
        results = []
        for run in range(args.runs):
            start = time.perf_counter()
            write_animation(anim, out, **options)
            seconds = time.perf_counter() - start
            info = gltf.decode(out)["info"]
            results.append({"run": run, "seconds": round(seconds, 3), "bytes": out.stat().st_size,
                            "morph_targets": info["morphTargets"], "error": info["reconstructionError"]})
            print(f"run {run}: {seconds:.2f} s, {out.stat().st_size / 1e6:.2f} MB, K={info['morphTargets']}, "
                  f"largest vertex error {info['reconstructionError']:.2e} of the face size "
                  f"(tolerance {tolerance:g})", flush=True)
        audio = info.get("audio", {})
        print(f"MP3: {audio.get('bitrate')} kbit/s at {audio.get('sampleRate')} Hz, encoder delay "
              f"{audio.get('delayCompensated')} samples compensated")
        report, why = run_gltf_validator(out)
        if report is None:
            print(f"glTF-Validator: not run ({why})")
        else:
            issues = report["issues"]
            print(f"glTF-Validator {report.get('validatorVersion')}: {issues['numErrors']} errors, "
                  f"{issues['numWarnings']} warnings, {issues['numInfos']} infos")
    best = min(r["seconds"] for r in results)
    size = results[-1]["bytes"]
    print(json.dumps({"benchmark": "glb_export", "frames": anim.num_frames, "vertices": anim.num_vertices,
                      "best_seconds": best,
                      "median_seconds": float(np.median([r["seconds"] for r in results])),
                      "bytes": size, "size_ok": size <= 5_000_000, "time_ok": best <= 3.0}))


if __name__ == "__main__":
    main()
