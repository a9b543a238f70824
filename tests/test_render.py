"""Preview videos: streams and durations read back with ffmpeg, pixels decoded, compare layout, errors."""

from __future__ import annotations

import re
import subprocess
import sys

import imageio_ffmpeg
import numpy as np
import pytest

from facegen.animation import Animation
from facegen.errors import FacegenError
from facegen.exchange import write_animation
from facegen.face.mesh import Mesh, write_mesh
from facegen.render import render, render_animation, render_still
from facegen.render.overlay import TEXT, compare_overlay
from facegen.render.raster import BACKGROUND, Renderer, frame_cameras, heat_colors
from facegen.render.scene import picture_colors
from facegen.runtime import SILENT

FPS = 25.0
RATE = 16000
FRAMES = 20  # frames 0..9 silent (rest pose), 10..19 voiced (mouth open, a tone)
SIZE = 128
FFMPEG = imageio_ffmpeg.get_ffmpeg_exe()


def talking_clip(mesh: Mesh, frames: int = FRAMES) -> Animation:
    """The mesh at rest for the first half; in the second half its lower lip region drops by 4% of the face
    size while a 330 Hz tone plays. Silence in the first half."""
    vertices = np.repeat(mesh.vertices[None], frames, 0).astype(np.float32)
    vertices[frames // 2 :, lower_lip(mesh), 1] -= 0.04 * mesh.size
    t = np.arange(round(frames / FPS * RATE)) / RATE
    audio = np.where(t >= frames // 2 / FPS, 0.3 * np.sin(2 * np.pi * 330 * t), 0.0).astype(np.float32)
    return Animation(vertices, mesh.faces, FPS, mesh.vertices.copy(), audio, RATE, dict(mesh.regions))


def lower_lip(mesh: Mesh) -> np.ndarray:
    lips = np.asarray(mesh.regions["lips"])
    return lips[mesh.vertices[lips, 1] <= np.median(mesh.vertices[lips, 1])]


def streams(path) -> list[str]:
    """The 'Stream #..' lines ffmpeg prints for a file."""
    err = subprocess.run(
        [FFMPEG, "-hide_banner", "-i", str(path)], capture_output=True, text=True, check=False
    ).stderr
    return [line.strip() for line in err.splitlines() if line.strip().startswith("Stream #")]


def decode_frames(path) -> np.ndarray:
    """All video frames as [N, H, W, 3] uint8 RGB."""
    reader = imageio_ffmpeg.read_frames(str(path))
    width, height = next(reader)["size"]
    return np.stack([np.frombuffer(f, np.uint8).reshape(height, width, 3) for f in reader])


def decode_audio(path, rate: int = 48000) -> np.ndarray:
    """The audio stream decoded to mono float32 at `rate`."""
    out = subprocess.run(
        [
            FFMPEG,
            "-v",
            "error",
            "-i",
            str(path),
            "-map",
            "0:a:0",
            "-f",
            "f32le",
            "-ac",
            "1",
            "-ar",
            str(rate),
            "pipe:1",
        ],
        capture_output=True,
        check=True,
    ).stdout
    return np.frombuffer(out, np.float32)


def region_box(mesh: Mesh, region: str, view: int = 0, pad: int = 2) -> tuple[slice, slice]:
    """Pixel rows and columns (in the first, front panel) covered by a region of the rest pose."""
    cam = frame_cameras(mesh.vertices, ("front", "three_quarter"), SIZE)[view]
    xy, _ = cam.project(mesh.vertices[mesh.regions[region]])
    x0, y0 = np.floor(xy.min(0)).astype(int) - pad
    x1, y1 = np.ceil(xy.max(0)).astype(int) + pad
    offset = view * SIZE
    return slice(max(y0, 0), min(y1, SIZE)), slice(max(x0, 0) + offset, min(x1, SIZE) + offset)


@pytest.fixture(params=["grid", "biwi"])
def face(request) -> Mesh:
    return request.getfixturevalue(f"{request.param}_mesh" if request.param == "grid" else "biwi_template")


@pytest.mark.parametrize("audio_seconds", [FRAMES / FPS, 0.6, 1.5])  # the clip's, shorter (padded), longer
def test_video_and_audio_streams_last_the_clip(grid_mesh, tmp_path, audio_seconds):
    anim = talking_clip(grid_mesh)
    n = round(audio_seconds * RATE)
    anim.audio = np.pad(anim.audio, (0, max(0, n - len(anim.audio))))[:n]
    result = render_animation(anim, tmp_path / "clip.mp4", size=SIZE, reporter=SILENT)
    assert result.path.is_file() and (result.width, result.height, result.frames) == (2 * SIZE, SIZE, FRAMES)
    lines = streams(result.path)
    video = [s for s in lines if "Video:" in s]
    audio = [s for s in lines if "Audio:" in s]
    assert len(video) == 1 and len(audio) == 1, lines
    assert "h264" in video[0] and "yuv420p" in video[0] and f"{2 * SIZE}x{SIZE}" in video[0]
    assert re.search(r"\b25 fps\b", video[0]) and "aac" in audio[0]

    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(result.path))
    assert frames == FRAMES and abs(seconds - FRAMES / FPS) <= 1 / FPS
    sound = decode_audio(result.path)
    assert abs(len(sound) / 48000 - FRAMES / FPS) <= 1 / FPS
    # the sound is the clip's, in sync: silent first half, the tone (RMS 0.3/sqrt 2) in the second
    half, margin, end = len(sound) // 2, int(0.05 * 48000), round(min(audio_seconds, FRAMES / FPS) * 48000)
    assert np.sqrt(np.mean(sound[: half - margin] ** 2)) < 0.01
    assert abs(np.sqrt(np.mean(sound[half + margin : end - margin] ** 2)) - 0.3 / np.sqrt(2)) < 0.03
    assert np.sqrt(np.mean(sound[end + margin :] ** 2)) < 0.01 if end + margin < len(sound) else True


def test_frames_are_shaded_faces_on_the_background(grid_mesh, tmp_path):
    result = render_animation(talking_clip(grid_mesh), tmp_path / "clip.mp4", size=SIZE, reporter=SILENT)
    frames = decode_frames(result.path).astype(np.float32)
    assert frames.shape == (FRAMES, SIZE, 2 * SIZE, 3)
    background = np.asarray(BACKGROUND) * 255
    assert np.abs(frames[:, :3, :3] - background).max() < 6  # corners are the background
    for panel in (frames[:, :, :SIZE], frames[:, :, SIZE:]):
        assert panel.std(axis=(1, 2, 3)).min() > 20  # not blank
        face_pixels = (np.abs(panel - background).max(-1) > 40).mean(axis=(1, 2))
        assert face_pixels.min() > 0.2  # the face fills a good part of each view
        shades = panel[0][np.abs(panel[0] - background).max(-1) > 40].mean(-1)
        assert shades.max() - shades.min() > 40  # shaded, not a flat silhouette


def test_mouth_pixels_change_between_silent_and_voiced_frames(face, tmp_path):
    result = render_animation(talking_clip(face), tmp_path / "clip.mp4", size=SIZE, reporter=SILENT)
    frames = decode_frames(result.path).astype(np.float32)
    silent, voiced = frames[FRAMES // 2 - 3], frames[FRAMES - 3]
    rows, cols = region_box(face, "lips")
    mouth_change = np.abs(voiced[rows, cols] - silent[rows, cols]).mean()
    assert mouth_change > 8, mouth_change
    rows, cols = region_box(face, "upper_face")
    still_change = np.abs(voiced[rows, cols] - silent[rows, cols]).mean()
    assert still_change < 2.5, still_change  # only codec noise where nothing moved
    # silent frames are all the same pose: the camera does not move with the animation
    assert np.abs(frames[1] - frames[FRAMES // 2 - 1]).mean() < 1.5


def test_compare_is_twice_as_wide_with_the_error_painted_on_b(face, tmp_path):
    a = talking_clip(face)
    b = Animation(np.repeat(face.vertices[None], FRAMES, 0), face.faces, FPS, face.vertices.copy())
    normal = render_animation(a, tmp_path / "a.mp4", size=SIZE, reporter=SILENT)
    result = render_animation(a, tmp_path / "ab.mp4", size=SIZE, compare=b, reporter=SILENT)
    assert (result.width, result.height) == (2 * normal.width, normal.height) == (4 * SIZE, SIZE)
    frames = decode_frames(result.path).astype(np.float32)
    assert frames.shape == (FRAMES, SIZE, 4 * SIZE, 3)
    assert result.error_scale == pytest.approx(0.04 * face.size, rel=1e-4)  # the lips' drop
    assert any("Audio:" in s for s in streams(result.path))  # A's audio

    a_half = frames[:, :, : 2 * SIZE]
    assert np.abs(a_half - decode_frames(normal.path)).mean() < 1.5  # the left half is the normal video
    # B's front view (third panel) at B's vertices: red where A's lower lip dropped, grey elsewhere
    cam = frame_cameras(face.vertices, ("front", "three_quarter"), SIZE)[0]
    redness = frames[..., 0] - frames[..., 2]

    def b_redness(t: int, vertices: np.ndarray) -> float:
        xy, _ = cam.project(face.vertices[vertices])
        x, y = np.clip(np.round(xy - 0.5).astype(int), 0, SIZE - 1).T
        return float(np.median(redness[t, y, x + 2 * SIZE]))

    moved = lower_lip(face)
    assert b_redness(FRAMES - 3, moved) > b_redness(2, moved) + 60
    still = face.regions["upper_face"]
    assert abs(b_redness(FRAMES - 3, still) - b_redness(2, still)) < 4


@pytest.mark.parametrize("size", [SIZE, 512])
def test_compare_captions_are_text_in_the_title_strips_and_a_colour_bar(size):
    views, vmax, face_size = 2, 0.0123, 1.5
    half, width = size * views, 2 * size * views
    labels = ("A: prediction.usda", "B: " + "ground_truth_" * 20 + ".npy")  # B's far too long for its half
    ys, xs, rgb = compare_overlay(size, views, vmax, face_size, labels)
    assert len(ys) == len(xs) == len(rgb) and rgb.dtype == np.uint8
    assert ys.min() >= 0 and ys.max() < size and xs.min() >= 0 and xs.max() < width  # inside the frame
    ink = np.abs(rgb.astype(np.float32) - np.asarray(TEXT) * 255).max(-1) < 40  # text-coloured pixels
    strip = size // 8  # the title strip: rows above the face (which fills the middle 84%)
    for left, right in ((0, half), (half, width)):
        title = ink & (ys < strip) & (xs >= left) & (xs < right)
        rows, cols = np.ptp(ys[title]) + 1, np.ptp(xs[title]) + 1
        assert title.sum() > 20 and 6 <= rows < strip and cols > 4 * rows  # a line of legible text
        assert xs[title].max() < right - 2  # cut to fit its half
    assert not ((ys > strip) & (ys < size - strip)).any()  # nothing over the face
    assert not ((ys >= size - strip) & (xs < half)).any()  # the scale line is in B's half only
    # the colour bar: one unbroken run of pixels along a bottom row, grey (0) on the left to red (the top)
    red = (ys >= size - strip) & (rgb[:, 0].astype(int) > rgb[:, 2].astype(int) + 60)
    row = int(np.median(ys[red]))
    run = np.flatnonzero(ys == row)
    run = run[np.argsort(xs[run])]
    breaks = np.flatnonzero(np.diff(xs[run]) > 1)
    longest = max(np.split(run, breaks + 1), key=len)
    ends = heat_colors(np.array([0.0, 1.0]), 1.0)
    assert len(longest) > size // 4
    assert np.abs(rgb[longest[[0, -1]]] / 255 - ends).max() < 0.02
    assert (ink & (ys >= size - strip) & (xs > width - size // 2)).sum() > 20  # the scale's top value
    # the captions say what they are given: other labels or another scale, other pixels
    other = compare_overlay(size, views, 2 * vmax, face_size, ("A: other.usda", labels[1]))
    assert len(other[0]) != len(ys) or not np.array_equal(other[2], rgb)


def test_compare_frame_counts_topology_and_fps(grid_mesh, tmp_path):
    a = talking_clip(grid_mesh)
    shorter = Animation(a.vertices[:-2], a.faces, FPS, a.template)
    result = render_animation(a, tmp_path / "ab.mp4", size=SIZE, compare=shorter, reporter=SILENT)
    assert result.frames == FRAMES - 2 and any("first 18" in n for n in result.notes)
    assert imageio_ffmpeg.count_frames_and_secs(str(result.path))[0] == FRAMES - 2

    other = Animation(a.vertices[:, :-1], a.faces[:-2], FPS, a.template[:-1])
    with pytest.raises(FacegenError, match="same mesh topology"):
        render_animation(a, tmp_path / "x.mp4", size=SIZE, compare=other, reporter=SILENT)
    flipped = Animation(a.vertices, a.faces[:, ::-1].copy(), FPS, a.template)
    with pytest.raises(FacegenError, match="same mesh topology"):
        render_animation(a, tmp_path / "x.mp4", size=SIZE, compare=flipped, reporter=SILENT)
    with pytest.raises(FacegenError, match="not the same clip"):
        render_animation(
            a,
            tmp_path / "x.mp4",
            size=SIZE,
            compare=Animation(a.vertices[:5], a.faces, FPS, a.template),
            reporter=SILENT,
        )
    with pytest.raises(FacegenError, match="fps"):
        render_animation(
            a,
            tmp_path / "x.mp4",
            size=SIZE,
            reporter=SILENT,
            compare=Animation(a.vertices, a.faces, 30.0, a.template),
        )
    assert not (tmp_path / "x.mp4").exists()


def test_render_files_usd_glb_and_npy_with_template(grid_mesh, tmp_path):
    anim = talking_clip(grid_mesh)
    write_animation(anim, tmp_path / "clip.usda")
    write_animation(anim, tmp_path / "clip.glb")
    write_animation(anim, tmp_path / "truth.npy", write_audio=False)
    write_mesh(grid_mesh, tmp_path / "face.ply")
    for name in ("clip.usda", "clip.glb"):
        result = render(tmp_path / name, tmp_path / f"{name}.mp4", size=SIZE, views="front", reporter=SILENT)
        assert (result.width, result.height, result.frames, result.has_audio) == (SIZE, SIZE, FRAMES, True)
        assert abs(len(decode_audio(result.path)) / 48000 - FRAMES / FPS) <= 1 / FPS
    result = render(
        tmp_path / "truth.npy",
        tmp_path / "npy.mp4",
        size=SIZE,
        template=tmp_path / "face.ply",
        reporter=SILENT,
    )
    assert (result.width, result.frames, result.has_audio) == (2 * SIZE, FRAMES, False)
    assert [s for s in streams(result.path) if "Audio:" in s] == []
    # a .npy comparison takes the input's template and fps
    result = render(
        tmp_path / "clip.usda",
        tmp_path / "cmp.mp4",
        size=SIZE,
        compare=tmp_path / "truth.npy",
        reporter=SILENT,
    )
    assert result.width == 4 * SIZE and "identical" in " ".join(result.notes)


def test_npy_of_the_default_model_renders_without_model(tmp_path):
    """`facegen render x.npy` with no --model/--template: the built-in model's face when the vertex counts
    match (what `facegen animate -o x.npy` writes); through the CLI as users run it."""
    from facegen.bundle import load_bundle

    face = load_bundle(None).template
    anim = talking_clip(Mesh(face.vertices, face.faces, {"lips": face.regions["lips"]}), frames=4)
    write_animation(anim, tmp_path / "line.npy", write_audio=False)
    done = subprocess.run([sys.executable, "-m", "facegen", "render", str(tmp_path / "line.npy"), "-o",
                           str(tmp_path / "line.mp4"), "--size", "64", "--views", "front", "-q"],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert decode_frames(tmp_path / "line.mp4").shape == (4, 64, 64, 3)


@pytest.mark.parametrize(
    ("name", "kwargs", "message"),
    [
        ("clip.npy", {}, "120 per frame, and the built-in model's face has 23370: pass the template mesh"),
        ("missing.usda", {}, "does not exist"),
        ("clip.txt", {}, "unknown extension"),
        ("broken.usda", {}, "broken.usda"),
        ("clip.usda", {"size": 100 + 1}, "even number"),
        ("clip.usda", {"views": "front,side"}, "unknown view side"),
        ("clip.usda", {"output": "clip.gif"}, r"\.mp4"),
    ],
)
def test_bad_input_is_one_line_facegen_error(grid_mesh, tmp_path, name, kwargs, message):
    anim = talking_clip(grid_mesh)
    write_animation(anim, tmp_path / "clip.usda")
    write_animation(anim, tmp_path / "clip.npy")
    (tmp_path / "clip.txt").write_text("not an animation")
    (tmp_path / "broken.usda").write_text("#usda 1.0\n( this is not usd")
    before = set(tmp_path.iterdir())
    output = tmp_path / kwargs.pop("output", "out.mp4")
    with pytest.raises(FacegenError, match=message) as info:
        render(tmp_path / name, output, reporter=SILENT, **kwargs)
    assert "\n" not in str(info.value)
    assert set(tmp_path.iterdir()) == before  # nothing written


class _InterruptAt(np.ndarray):
    """Frames that raise KeyboardInterrupt (as Ctrl-C would) when frame `at` is rendered."""

    at = 7

    def __getitem__(self, key):
        if isinstance(key, (int, np.integer)) and key == self.at:
            raise KeyboardInterrupt
        return super().__getitem__(key)


@pytest.mark.parametrize("threads", [1, 2])
def test_interrupted_render_leaves_no_file(grid_mesh, tmp_path, threads):
    anim = talking_clip(grid_mesh)
    anim.vertices = anim.vertices.view(_InterruptAt)
    with pytest.raises(KeyboardInterrupt):
        render_animation(anim, tmp_path / "clip.mp4", size=SIZE, reporter=SILENT, threads=threads)
    assert list(tmp_path.iterdir()) == []


def test_cameras_frame_the_template_from_the_front_and_three_quarter(face):
    front, three_quarter = frame_cameras(face.vertices, ("front", "three_quarter"), SIZE)
    extents = []
    for cam in (front, three_quarter):
        xy, depth = cam.project(face.vertices)
        assert (depth > 0).all()
        assert xy.min() >= 0.05 * SIZE and xy.max() <= 0.95 * SIZE  # inside, with a margin
        extents.append(max(np.ptp(xy[:, 0]), np.ptp(xy[:, 1])) / SIZE)
    assert min(extents) > 0.6 and max(extents) > 0.8  # filling the views (one distance for both)
    centre = (face.vertices.min(0) + face.vertices.max(0)) / 2
    assert front.eye[2] > face.vertices[:, 2].max() and abs(front.eye[0] - centre[0]) < 1e-3 * face.size
    assert front.rotation[2] @ [0, 0, -1] == pytest.approx(1.0)  # looks along -Z, at the face
    yaw = np.degrees(np.arctan2(-three_quarter.rotation[2][0], -three_quarter.rotation[2][2]))
    assert yaw == pytest.approx(40.0)
    assert np.linalg.norm(front.eye - centre) == pytest.approx(
        np.linalg.norm(three_quarter.eye - centre), 0.2
    )


def test_still_png_and_identical_renders(grid_mesh, tmp_path):
    path = render_still(grid_mesh, tmp_path / "still.png", size=SIZE)
    reader = imageio_ffmpeg.read_frames(str(path))
    assert tuple(next(reader)["size"]) == (2 * SIZE, SIZE)
    image = np.frombuffer(next(reader), np.uint8).reshape(SIZE, 2 * SIZE, 3)
    colors = picture_colors(grid_mesh.faces, grid_mesh.regions, grid_mesh.num_vertices)  # names lips: tinted
    assert colors is not None
    direct = Renderer(grid_mesh.faces, grid_mesh.vertices, SIZE).render(grid_mesh.vertices, colors)
    assert np.array_equal(image, direct)  # PNG is lossless
    assert image.std() > 20


def test_fine_mesh_renders_without_cracks():
    """Thousands of jittered sub-pixel triangles: shared edges leave no background pixel inside the sheet."""
    n = 120
    xs, ys = np.meshgrid(np.linspace(-0.5, 0.5, n), np.linspace(-0.5, 0.5, n))
    jitter = np.random.default_rng(0).uniform(-0.3, 0.3, (2, n, n)) / n
    jitter[:, [0, -1], :] = 0
    jitter[:, :, [0, -1]] = 0
    vertices = (
        np.stack([xs + jitter[0], ys + jitter[1], np.zeros_like(xs)], -1).reshape(-1, 3).astype(np.float32)
    )
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None]).ravel()
    faces = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)]).astype(
        np.int32
    )
    image = Renderer(faces, vertices, SIZE, views=("front",)).render(vertices).astype(np.float32)
    inside = image[SIZE // 4 : 3 * SIZE // 4, SIZE // 4 : 3 * SIZE // 4].sum(-1)
    assert len(faces) / (SIZE * 0.84) ** 2 > 1.5  # more than one triangle per pixel
    assert inside.min() > 0.97 * np.median(inside)  # a flat lit sheet: no dark (background) speckles
