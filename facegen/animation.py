"""The in-memory animation every writer reads and every reader returns, and the checks writers run on it."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from facegen.errors import FacegenError
from facegen.face.mesh import Mesh
from facegen.face.parts import PartDrivers, PartTrack

DEFAULT_FPS = 25.0  # the frame rate of a file that states none (BIWI's)


@dataclass
class Animation:
    """A face mesh animation with its audio.

    vertices: [T, V, 3] float32 positions (template + offsets), one per frame at `fps`; a [T, V, 3] array or
              a FrameStream (inference.py) that computes frames block by block (`streamed`).
    faces:    [F, 3] int32 triangle list of the template.
    template: [V, 3] rest pose; with `faces` and `regions` it is the template Mesh (`mesh`, `from_mesh`).
    audio:    mono float32 samples at `sample_rate` (None when there is none), the clip's sound.
    head:     [T, 3] float32 rotation of the whole head per frame, (yaw, pitch, roll) degrees about
              `head_pivot` (facegen.head), or None: a still head. The vertices stay face-local; writers put
              it on a transform where the format has one.
    parts:    what moves the parts beside the face (facegen.face.parts: eyeballs with irises, teeth, tongue):
              the gaze and the tongue's weights per frame, or None: no parts (files read back, a face without
              the regions they are fitted to). `part_meshes()` gives the parts and their motion.

    The template's fields stay flat (rather than one `mesh: Mesh` field) because they are what users,
    writers and readers of Animation read: `anim.faces`, `anim.template`, `anim.regions`.
    """

    vertices: np.ndarray
    faces: np.ndarray
    fps: float
    template: np.ndarray
    audio: np.ndarray | None = None
    sample_rate: int = 16000
    regions: dict[str, np.ndarray] = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    head: np.ndarray | None = None  # [T, 3] (yaw, pitch, roll) degrees about head_pivot (facegen.head)
    head_pivot: np.ndarray | None = None  # [3] mesh units
    parts: PartDrivers | None = None  # what moves the eyes, teeth, tongue (face/parts.py); None: no parts

    @classmethod
    def from_mesh(cls, mesh: Mesh, vertices: np.ndarray, fps: float, **fields) -> Animation:
        """The animation of `mesh` (its vertices as float32 rest pose, faces as int32, regions);
        `fields` are the other fields (audio, sample_rate, metadata)."""
        return cls(vertices=vertices, faces=np.asarray(mesh.faces, dtype=np.int32), fps=fps,
                   template=np.asarray(mesh.vertices, dtype=np.float32), regions=dict(mesh.regions), **fields)

    @property
    def mesh(self) -> Mesh:
        """The template as a Mesh (rest pose, faces, regions)."""
        return Mesh(self.template, self.faces, self.regions)

    @property
    def num_frames(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def num_vertices(self) -> int:
        return int(self.vertices.shape[1])

    @property
    def duration(self) -> float:
        return self.num_frames / self.fps

    @property
    def size(self) -> float:
        """Bounding-box diagonal of the template: the unit for relative tolerances."""
        return self.mesh.size

    @property
    def streamed(self) -> bool:
        """True when `vertices` is a FrameStream: frames are computed on demand, never all held at once."""
        return hasattr(self.vertices, "blocks")

    def part_meshes(self) -> list[PartTrack]:
        """The parts beside the face and their motion over the frames (facegen.face.parts), [] without
        `parts` or the regions they are fitted to; the jaw's motion is read from the chin's vertices."""
        from facegen.face import parts as p

        if self.parts is None or not p.has_parts(self.regions):
            return []
        cached = getattr(self, "_part_tracks", None)
        if cached is not None and cached[0] is self.vertices:
            return cached[1]
        chin = p.chin_points(self.template, self.regions)
        frames = self.vertices.points(chin) if self.streamed else np.asarray(self.vertices)[:, chin]
        hinge = np.asarray(self.template, np.float64)[np.asarray(self.regions["jaw_hinge"])].mean(0)
        angle, hinge_at = p.jaw_motion(np.asarray(self.template, np.float64)[chin], frames, hinge)
        parts = p.face_parts(self.template, self.regions, self.faces)
        tracks = p.part_tracks(parts, self.parts, angle, hinge_at)
        self._part_tracks = (self.vertices, tracks)
        return tracks

    def frame_blocks(self, block_frames: int | None = None,
                     ahead: bool = False) -> Iterator[tuple[int, np.ndarray]]:
        """(first frame, [n, V, 3] float32 frames) for consecutive blocks, for arrays and streams alike: a
        FrameStream computes one block at a time (`block_frames`, default its own; `ahead`: the next one in a
        thread while the caller uses this one), an array is one block (or blocks of `block_frames`)."""
        if self.streamed:
            stream = self.vertices
            yield from stream.blocks(block_frames, ahead=True) if ahead else stream.blocks(block_frames)
            return
        frames = np.ascontiguousarray(self.vertices, dtype=np.float32)
        step = block_frames or max(len(frames), 1)
        for start in range(0, len(frames), step):
            yield start, frames[start : start + step]


def check_animation(anim: Animation) -> None:
    """Refuse an Animation no writer can store: wrong shapes, no frames, bad fps, faces out of range."""
    vertices = anim.vertices if anim.streamed else np.asarray(anim.vertices)  # a FrameStream stays lazy
    faces = np.asarray(anim.faces)
    if len(vertices.shape) != 3 or vertices.shape[2] != 3 or vertices.shape[0] == 0 or vertices.shape[1] == 0:
        raise FacegenError(f"animation vertices must be [T, V, 3] with T, V > 0, got {list(vertices.shape)}")
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.shape[0] == 0:
        raise FacegenError(f"animation faces must be [F, 3] triangles, got {list(faces.shape)}")
    if faces.min() < 0 or faces.max() >= vertices.shape[1]:
        raise FacegenError(f"animation faces index vertices outside 0..{vertices.shape[1] - 1}")
    if np.asarray(anim.template).shape != vertices.shape[1:]:
        raise FacegenError(
            f"animation template is {list(np.shape(anim.template))}, frames are {list(vertices.shape[1:])}"
        )
    if not (np.isfinite(anim.fps) and anim.fps > 0):
        raise FacegenError(f"animation fps must be a positive number, got {anim.fps}")
    if anim.audio is not None and np.asarray(anim.audio).ndim != 1:
        raise FacegenError(f"animation audio must be mono (1-D), got shape {list(np.shape(anim.audio))}")
    if anim.audio is not None and not (
        isinstance(anim.sample_rate, int | np.integer) and anim.sample_rate > 0
    ):
        raise FacegenError(f"animation sample rate must be a positive integer, got {anim.sample_rate!r}")


MAX_FPS = 240.0  # output frames per second at most


def check_fps(fps: float | None) -> float | None:
    """An output frame rate: None (the network's) or a finite number in (0, 240]."""
    import math

    if fps is None:
        return None
    number = isinstance(fps, int | float) and not isinstance(fps, bool)
    if not number or not math.isfinite(fps) or not 0 < fps <= MAX_FPS:
        raise FacegenError(f"the frame rate must be a number of frames per second in (0, {MAX_FPS:g}], got "
                           f"{fps!r}: e.g. 24, 25, 30 or 60", param="fps")
    return float(fps)
