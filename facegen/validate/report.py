"""The result of `facegen validate`: named checks (PASS / FAIL / WARN) in one Report, and what the caller
expects of the file (`Expected`)."""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from facegen.animation import Animation
    from facegen.face.mesh import Mesh

DEFAULT_MAX_DISPLACEMENT = 0.25


@dataclass
class Check:
    name: str
    ok: bool
    detail: str
    severity: str = "error"  # "error": failing it fails the report; "warning": shown only

    @property
    def label(self) -> str:
        if self.ok:
            return "PASS"
        return "FAIL" if self.severity == "error" else "WARN"


@dataclass
class Report:
    path: str
    checks: list[Check] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(c.ok for c in self.checks if c.severity == "error")

    @property
    def failures(self) -> list[Check]:
        return [c for c in self.checks if not c.ok and c.severity == "error"]

    @property
    def warnings(self) -> list[Check]:
        return [c for c in self.checks if not c.ok and c.severity != "error"]

    def check(self, name: str) -> Check | None:
        """The first check called `name` (None when it did not run)."""
        return next((c for c in self.checks if c.name == name), None)

    def add(self, name: str, ok: bool, detail: str, severity: str = "error") -> bool:
        self.checks.append(Check(name, bool(ok), detail, severity))
        return bool(ok)

    def to_text(self) -> str:
        head = "OK" if self.ok else "FAILED"
        counts = f"{len(self.checks)} checks, {len(self.failures)} failed, {len(self.warnings)} warnings"
        lines = [f"{self.path}: {head} ({counts})"]
        width = min(max((len(c.name) for c in self.checks), default=0), 14)
        lines += [f"  {c.label}  {c.name:<{width}}  {c.detail}" for c in self.checks]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"path": self.path, "ok": self.ok, "checks": [asdict(c) for c in self.checks]}

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent)


@dataclass(frozen=True)
class Expected:
    """What the file must match: the template mesh, the frame rate, the audio (`audio_path` replaces the
    file's own), how far a vertex may move (x the rest pose's bounding-box diagonal) and, for glTF, the
    source animation (a file or an Animation) its morph targets must reproduce."""

    template: Mesh | None = None
    fps: float | None = None
    audio_path: str | os.PathLike | None = None
    require_audio: bool = True
    max_displacement: float = DEFAULT_MAX_DISPLACEMENT
    reference: str | os.PathLike | Animation | None = None
