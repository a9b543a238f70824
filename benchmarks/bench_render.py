"""Benchmark: render a 5 s clip (125 frames at 25 fps, the BIWI template, 23,370 vertices) to a preview MP4.

Target: <= 10 s on 2 CPU cores for the default video (512 px per view, front + three-quarter, 1024 x 512,
audio muxed). Prints wall-clock and CPU seconds (this process + ffmpeg) of each run; the first run also
loads (or, on a fresh install, compiles) the numba kernels. Skips when ../shared/biwi is absent.

    python benchmarks/bench_render.py [--runs 2] [--compare] [--size 512] [--threads N]
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BIWI_DIR = Path(__file__).resolve().parents[2] / "shared" / "biwi"
FPS, FRAMES, RATE = 25.0, 125, 16000


def talking_clip():
    """The BIWI template with its lip region opening and closing at 3 Hz, and a matching tone."""
    from facegen.animation import Animation
    from facegen.face.mesh import read_mesh, read_region

    mesh = read_mesh(BIWI_DIR / "BIWI.ply")
    lips = read_region(BIWI_DIR / "lve.txt")
    lower = lips[mesh.vertices[lips, 1] < np.median(mesh.vertices[lips, 1])]
    t = np.arange(FRAMES) / FPS
    opening = 0.5 - 0.5 * np.cos(2 * np.pi * 3 * t)
    vertices = np.repeat(mesh.vertices[None], FRAMES, 0)
    vertices[:, lower, 1] -= (0.03 * mesh.size * opening)[:, None]
    s = np.arange(round(FRAMES / FPS * RATE)) / RATE
    audio = (0.3 * np.sin(2 * np.pi * 180 * s) * np.interp(s, t, opening)).astype(np.float32)
    return Animation(vertices.astype(np.float32), mesh.faces, FPS, mesh.vertices, audio, RATE)


def cpu_seconds() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--compare", action="store_true", help="also time a compare video (twice as wide)")
    args = parser.parse_args(argv)
    if not (BIWI_DIR / "BIWI.ply").is_file():
        print(f"bench_render: skipped ({BIWI_DIR} is absent)")
        return 0

    start = time.perf_counter()
    from facegen.animation import Animation
    from facegen.render import render_animation
    from facegen.runtime import SILENT, cores

    anim = talking_clip()
    print(
        f"bench_render: setup (imports, template) {time.perf_counter() - start:.2f} s; "
        f"{anim.num_frames} frames, {anim.num_vertices} vertices, {len(anim.faces)} triangles, "
        f"{args.threads or cores()} render threads"
    )
    rest = Animation(np.repeat(anim.template[None], FRAMES, 0), anim.faces, FPS, anim.template)
    cases = [("preview", None)] + ([("compare", rest)] if args.compare else [])
    with tempfile.TemporaryDirectory() as tmp:
        for name, other in cases:
            for run in range(args.runs):
                cpu, wall = cpu_seconds(), time.perf_counter()
                result = render_animation(
                    anim,
                    Path(tmp) / f"{name}.mp4",
                    size=args.size,
                    compare=other,
                    reporter=SILENT,
                    threads=args.threads,
                )
                wall, cpu = time.perf_counter() - wall, cpu_seconds() - cpu
                mb = result.path.stat().st_size / 1e6
                print(
                    f"bench_render: {name} run {run + 1}: {result.width}x{result.height}, "
                    f"{result.frames} frames ({result.duration:.1f} s clip) in {wall:.2f} s wall, "
                    f"{cpu:.2f} s CPU ({1000 * wall / result.frames:.0f} ms/frame), {mb:.1f} MB"
                    + ("  [target <= 10 s]" if name == "preview" else "")
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
