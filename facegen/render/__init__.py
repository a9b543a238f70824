"""Preview videos and stills of an animation: offscreen shaded renders, its audio, as H.264 MP4 or PNG.

The library entry points (the CLI's `facegen render` and `animate --preview`, plots' face images):
render (files or objects in, a video out), render_animation (an Animation to a video), render_still (one
frame to a PNG), render_image (a mesh to an array), check_output / check_views (option checks before work).
The pieces: raster.py draws a frame (camera, numba rasteriser, shading), overlay.py the compare captions,
video.py pipes frames to ffmpeg with the audio.

Layout: the normal video shows the views side by side, `size` pixels square each (front + three-quarter:
1024 x 512 by default). With a comparison (`compare=B`) the video is exactly twice as wide: the left half
is A's views as in the normal video, the right half is B in the same views, painted with the per-vertex
error |A - B| (grey at 0 → yellow → orange → red at the scale's top). A title strip names A and B and a
colour bar at the bottom states the scale, in the mesh's units and in % of the face size (the template's
bounding-box diagonal).

A 5 s clip (125 frames x 2 views) costs ~5.5 s of CPU including H.264 encoding: ~3 s on two free cores.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facegen.animation import Animation, check_animation
from facegen.atomic import atomic_path
from facegen.errors import FacegenError
from facegen.face.mesh import Mesh, read_mesh
from facegen.render.overlay import compare_overlay
from facegen.render.raster import (
    DEFAULT_VIEWS,
    Renderer,
    check_size,
    check_views,
    heat_colors,
    render_image,
)
from facegen.render.scene import Scene, picture_colors
from facegen.render.video import check_output, clip_audio, encode, frames_in_order
from facegen.runtime import BARS, Reporter, cores

__all__ = ["RenderResult", "check_output", "check_views", "render", "render_animation", "render_image",
           "render_still"]


@dataclass
class RenderResult:
    """What a render wrote: the file, its picture size, frame count and rate, and notes for the user."""

    path: Path
    width: int
    height: int
    frames: int
    fps: float
    has_audio: bool
    seconds: float  # wall-clock time of the render
    error_scale: float | None = None  # compare mode: the heat map's top value (mesh units)
    notes: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return self.frames / self.fps


def render_animation(
    anim: Animation,
    path: str | os.PathLike,
    *,
    size: int = 512,
    views: Sequence[str] = DEFAULT_VIEWS,
    compare: Animation | None = None,
    error_scale: float | None = None,
    labels: tuple[str, str] = ("A", "B"),
    reporter: Reporter = BARS,
    threads: int | None = None,
    supersample: int = 2,
) -> RenderResult:
    """Render `anim` to an MP4 at its fps with its audio: the views side by side, `size` px square each.

    compare: another animation of the same topology (ground truth, another model): the video is twice as
    wide, B beside A, B painted with the per-vertex error |A - B| on a scale from 0 to `error_scale`
    (default: the clip's largest error). Frame counts that differ by a few frames use the shorter clip
    (a note in the result); a topology mismatch is a FacegenError.
    """
    start = time.perf_counter()
    path = check_output(path)
    check_animation(anim)
    _check_finite(anim, "the animation")
    notes: list[str] = []
    scene = Scene(anim, parts=compare is None)  # the face and its parts (eyes, teeth, tongue)
    renderer = Renderer(scene.faces, scene.template, size, views, supersample)
    frames, audio_source = anim.num_frames, anim
    vmax = None
    if compare is not None:
        check_animation(compare)
        _check_finite(compare, "the comparison animation")
        frames = _check_comparable(anim, compare, labels, notes)
        if error_scale is not None and not error_scale > 0:
            raise FacegenError(f"the error scale must be a positive distance, got {error_scale}")
        vmax = (
            float(error_scale)
            if error_scale is not None
            else max(float(_vertex_errors(anim, compare, t).max()) for t in range(frames))
        )
        if not vmax > 0:
            vmax = max(anim.size, 1e-12) * 1e-3  # identical clips: any positive scale shows all grey
            notes.append("the two animations are identical")
        if anim.audio is None and compare.audio is not None:
            audio_source = compare
        overlay = compare_overlay(renderer.size, len(renderer.views), vmax, anim.size, labels)
    width = renderer.width * (2 if compare is not None else 1)
    height = renderer.size
    threads = cores() if threads is None else max(1, int(threads))

    base_colors = scene.colors

    def render_one(t: int) -> np.ndarray:
        frame = np.empty((height, width, 3), np.uint8)
        renderer.render_into(_posed(anim, t, scene), frame[:, : renderer.width], base_colors)
        if compare is not None:
            colors = heat_colors(_vertex_errors(anim, compare, t), vmax)
            renderer.render_into(_posed(compare, t), frame[:, renderer.width :], colors)
            frame[overlay[0], overlay[1]] = overlay[2]
        return frame

    audio = clip_audio(audio_source.audio, audio_source.sample_rate, frames, audio_source.fps)
    if audio is None:
        notes.append("the animation has no audio: the video is silent")
    rendered = frames_in_order(render_one, frames, threads)
    try:
        with atomic_path(path) as tmp:
            encode(rendered, frames, width, height, anim.fps, audio, audio_source.sample_rate, tmp, reporter)
    finally:
        rendered.close()  # on an error: stop the render threads before returning
    return RenderResult(
        path,
        width,
        height,
        frames,
        float(anim.fps),
        audio is not None,
        time.perf_counter() - start,
        vmax,
        notes,
    )


def _posed(anim: Animation, t: int, scene: Scene | None = None) -> np.ndarray:
    """Frame `t` as it is seen: the face-local vertices (and the `scene`'s parts) turned with the head
    (Animation.head) if it moves."""
    vertices = np.asarray(anim.vertices[t])
    if scene is not None:
        vertices = scene.points(vertices, t)
    if anim.head is None:
        return vertices
    from facegen.head import rotations

    pivot = np.asarray(anim.head_pivot, np.float64)
    turned = pivot + (vertices.astype(np.float64) - pivot) @ rotations(anim.head[t:t + 1])[0].T
    return turned.astype(np.float32)


def _vertex_errors(a: Animation, b: Animation, t: int) -> np.ndarray:
    """|A - B| per vertex at frame t (Euclidean distance, mesh units)."""
    return np.linalg.norm(
        np.asarray(a.vertices[t], np.float32) - np.asarray(b.vertices[t], np.float32), axis=-1
    )


def _check_finite(anim: Animation, what: str) -> None:
    bad = ~np.isfinite(np.asarray(anim.vertices)).all(axis=(1, 2))
    if bad.any():
        raise FacegenError(
            f"{what} has NaN or infinite vertex positions in frame {int(np.argmax(bad))}: re-export it"
        )


def _check_comparable(a: Animation, b: Animation, labels: tuple[str, str], notes: list[str]) -> int:
    """The number of frames to compare; a FacegenError for a different topology, fps or clip."""
    name_a, name_b = labels
    if (
        a.num_vertices != b.num_vertices
        or a.faces.shape != b.faces.shape
        or not np.array_equal(a.faces, b.faces)
    ):
        raise FacegenError(
            f"cannot compare {name_a} ({a.num_vertices} vertices, {len(a.faces)} triangles) with {name_b} "
            f"({b.num_vertices} vertices, {len(b.faces)} triangles): "
            "compare animations of the same mesh topology"
        )
    if abs(a.fps - b.fps) > 1e-6:
        raise FacegenError(
            f"{name_a} is at {a.fps:g} fps but {name_b} at {b.fps:g} fps: compare clips at one "
            "frame rate: resample one, or give the frame rate of a .npy file", param="fps"
        )
    if a.num_frames != b.num_frames:
        shorter, longer = sorted((a.num_frames, b.num_frames))
        if longer - shorter > max(5, round(0.1 * longer)):
            raise FacegenError(
                f"{name_a} has {a.num_frames} frames but {name_b} has {b.num_frames}: these are "
                "not the same clip; compare two animations of one utterance"
            )
        notes.append(
            f"{name_a} has {a.num_frames} frames and {name_b} {b.num_frames}: comparing the first {shorter}"
        )
        return shorter
    return a.num_frames


def _read_input(
    path: str | os.PathLike, template: Mesh | None = None, fps: float | None = None, what: str = "input"
) -> Animation:
    """Read an animation file for rendering, with one-line errors for the usual mistakes."""
    from facegen.exchange import format_of, read_animation

    path = Path(path)
    fmt = format_of(path)  # unknown extension → FacegenError naming the ones facegen reads
    if not path.is_file():
        raise FacegenError(f"{what} {path} does not exist: pass an animation file facegen wrote")
    if not fmt.holds_mesh and fmt.reads and template is None:  # vertex positions only (.npy)
        template = _default_template(path)
    return read_animation(path, template=template, fps=fps)


def _with_parts(anim: Animation) -> Animation:
    """A file facegen wrote, drawn as the preview draws it: a face without the regions its colours and parts
    fit to gets the built-in face's when it has its topology (so a .glb or .usd of it shows its lips, eye
    whites and mouth); one from speech (saccades in its metadata) gets its parts: the gaze from the
    saccades, the jaw read from its chin, the tongue at rest (files keep no phones)."""
    import json
    from dataclasses import replace

    from facegen.face.parts import PartDrivers, has_parts
    from facegen.gaze import Saccade, gaze_curve

    regions = anim.regions
    if not has_parts(regions):
        from facegen.face.template import load_template

        face = load_template()
        if face.num_vertices != anim.num_vertices or not np.array_equal(face.faces, anim.faces):
            return anim
        regions = face.regions
        anim = replace(anim, regions=dict(regions))
    saccades = anim.metadata.get("saccades")
    if anim.parts is not None or saccades is None:
        return anim
    try:
        found = [Saccade(*map(float, s)) for s in (json.loads(saccades) if isinstance(saccades, str)
                                                     else saccades)]
    except (TypeError, ValueError):
        return anim
    gaze = gaze_curve(found, anim.num_frames, anim.fps)
    return replace(anim, parts=PartDrivers(gaze, np.zeros((anim.num_frames, 2), np.float32)))


def _default_template(path: Path) -> Mesh:
    """The built-in model's template for a .npy of its vertex count (what `facegen animate` writes with the
    default model); any other count is a FacegenError asking for the mesh."""
    from facegen.bundle import read_template
    from facegen.exchange.npy import load_frames

    count = load_frames(path).shape[1] // 3
    template = read_template(None)
    if count != template.num_vertices:
        raise FacegenError(
            f"{path.name} stores only vertex positions, {count} per frame, and the built-in model's face has "
            f"{template.num_vertices}: pass the template mesh that gives its faces", param="template"
        )
    return template


def render(
    input: Animation | str | os.PathLike,
    output: str | os.PathLike,
    *,
    size: int = 512,
    views: Sequence[str] | str = DEFAULT_VIEWS,
    compare: Animation | str | os.PathLike | None = None,
    template: Mesh | str | os.PathLike | None = None,
    fps: float | None = None,
    error_scale: float | None = None,
    reporter: Reporter = BARS,
    threads: int | None = None,
) -> RenderResult:
    """Render an animation (object or file: .usd*, .glb/.gltf, .npy with `template`, else the built-in
    model's face when the vertex count is its own) to a preview video.

    compare: a second animation (object or file) of the same topology: see render_animation. A .npy
    comparison file uses the input's template when `template` is not given, and the input's fps.
    fps applies to files that store none (.npy).
    """
    path = check_output(output)
    views = check_views(views)
    check_size(size)
    mesh = template if template is None or isinstance(template, Mesh) else read_mesh(template)
    anim = input if isinstance(input, Animation) else _with_parts(_read_input(input, mesh, fps))
    label_a = "A" if isinstance(input, Animation) else f"A: {Path(input).name}"
    other, label_b = None, "B"
    if compare is not None:
        if isinstance(compare, Animation):
            other = compare
        else:
            compare = Path(compare)
            label_b = f"B: {compare.name}"
            from facegen.exchange import format_of

            stores_fps = format_of(compare).holds_fps
            own = mesh if mesh is not None else Mesh(np.asarray(anim.template, np.float32), anim.faces)
            other = _read_input(compare, own, None if stores_fps else anim.fps, what="comparison file")
    return render_animation(
        anim,
        path,
        size=size,
        views=views,
        compare=other,
        error_scale=error_scale,
        labels=(label_a, label_b),
        reporter=reporter,
        threads=threads,
    )


def render_still(
    input: Animation | Mesh,
    path: str | os.PathLike,
    *,
    frame: int = 0,
    size: int = 512,
    views: Sequence[str] | str = DEFAULT_VIEWS,
) -> Path:
    """Write one frame of an animation (or a mesh at rest) as a PNG, the views side by side."""
    from PIL import Image

    if isinstance(input, Mesh):
        vertices, faces, template = input.vertices, input.faces, input.vertices
    else:
        if not 0 <= frame < input.num_frames:
            raise FacegenError(f"frame {frame} is outside the clip's 0..{input.num_frames - 1}")
        scene = Scene(input)
        vertices, faces, template = _posed(input, frame, scene), scene.faces, scene.template
    colors = (scene.colors if not isinstance(input, Mesh)
              else picture_colors(input.faces, input.regions, len(vertices)))
    image = render_image(vertices, faces, template, size=size, views=check_views(views), colors=colors)
    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, "PNG")
    return Path(path)
