"""The in-memory animation every writer reads and every reader returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Animation:
    """A face mesh animation with its audio.

    vertices: [T, V, 3] float32 positions (template + offsets), one per frame at `fps`.
    faces:    [F, 3] int32 triangle list of the template.
    audio:    mono float32 samples at `sample_rate` (None when there is none), the clip's sound.
    """

    vertices: np.ndarray
    faces: np.ndarray
    fps: float
    template: np.ndarray
    audio: np.ndarray | None = None
    sample_rate: int = 16000
    regions: dict[str, np.ndarray] = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)

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
        return float(np.linalg.norm(self.template.max(0) - self.template.min(0)))
