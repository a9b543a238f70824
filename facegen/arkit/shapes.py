"""ARKit's 52 blend shapes as offsets of facegen's procedural face: `arkit_shapes(mesh) -> Shapes`, cached.

The deformations themselves are in facegen.arkit.deformers (on facegen.face.rig's Rig). Building them takes
1.2-1.6 s on the 23,370-vertex face, so the result is memoised in the process and stored on disk
(safetensors under $XDG_CACHE_HOME/facegen/arkit, default ~/.cache), keyed by a digest of the mesh's
vertices, faces and regions and of the deformers' source code; a damaged or foreign cache file is rebuilt,
an unwritable cache folder only costs the rebuild.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facegen.arkit.names import ARKIT_NAMES
from facegen.atomic import atomic_path
from facegen.errors import FacegenError
from facegen.face.mesh import Mesh
from facegen.face.regions import ARKIT_REGIONS
from facegen.runtime import cache_dir

# the code the shapes are made by: part of the cache key (the files' bytes, not their paths), so a changed
# deformation is never read from the cache
SOURCES = (Path(__file__).with_name("deformers.py"), Path(__file__).parents[1] / "face" / "rig.py")
_MEMO: dict[str, Shapes] = {}
_MEMO_SIZE = 4


@dataclass(frozen=True, eq=False)
class Shapes:
    """The 52 ARKit shapes of one face: `offsets` [52, V, 3] float32 (shape at weight 1 minus the template,
    mesh units, read-only), in `names` order (ARKIT_NAMES); `mm` mesh units per millimetre. `hidden`
    [1, V, 3] are offsets the ARKit fit solves for beside them, with either sign, and drops: the rig's motion
    no blend shape holds (the bulge of its jaw's turn off jawOpen's straight line, deformers.jaw_arc), so that
    the fit does not make it up out of ARKit shapes that mean something else."""

    names: tuple[str, ...]
    offsets: np.ndarray
    mm: float
    hidden: np.ndarray

    def offset(self, name: str) -> np.ndarray:
        """The offsets [V, 3] of the shape called `name` (ARKit lowerCamel)."""
        return self.offsets[self.names.index(name)]


def mesh_digest(mesh: Mesh) -> str:
    """A hash of the mesh's vertices, faces and regions and of the code in SOURCES: the cache key."""
    h = hashlib.sha256(b"".join(path.read_bytes() for path in SOURCES))
    h.update(np.ascontiguousarray(mesh.vertices, np.float32).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, np.int64).tobytes())
    for name in sorted(mesh.regions):
        h.update(name.encode() + b"\0")
        h.update(np.ascontiguousarray(mesh.regions[name], np.int64).tobytes())
    return h.hexdigest()[:24]


def cache_folder() -> Path:
    """Where built shapes are stored: runtime.cache_dir("arkit") ($XDG_CACHE_HOME/facegen/arkit)."""
    return cache_dir("arkit")


def _read(path: Path, num_vertices: int) -> Shapes | None:
    from safetensors import safe_open

    try:
        with safe_open(str(path), "np") as f:
            names = tuple((f.metadata() or {}).get("names", "").split(","))
            offsets = f.get_tensor("offsets")
            hidden = f.get_tensor("hidden")
            mm = float(f.get_tensor("mm")[0])
    except Exception:  # noqa: BLE001 - a damaged cache file is simply rebuilt
        return None
    if (names != ARKIT_NAMES or offsets.shape != (len(ARKIT_NAMES), num_vertices, 3)
            or hidden.shape != (1, num_vertices, 3) or offsets.dtype != np.float32
            or hidden.dtype != np.float32 or not np.isfinite(offsets).all() or not np.isfinite(hidden).all()
            or not mm > 0):
        return None
    return _frozen(offsets, mm, hidden)


def _write(path: Path, shapes: Shapes) -> None:
    from safetensors.numpy import save_file

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            save_file({"offsets": shapes.offsets, "hidden": shapes.hidden,
                       "mm": np.array([shapes.mm], np.float64)}, str(tmp),
                      metadata={"names": ",".join(shapes.names)})
    except (OSError, FacegenError):
        pass  # no cache: the next process builds the shapes again


def _frozen(offsets: np.ndarray, mm: float, hidden: np.ndarray) -> Shapes:
    offsets = np.ascontiguousarray(offsets, np.float32)
    hidden = np.ascontiguousarray(hidden, np.float32)
    offsets.setflags(write=False)
    hidden.setflags(write=False)
    return Shapes(ARKIT_NAMES, offsets, float(mm), hidden)


def check_regions(mesh: Mesh) -> None:
    """FacegenError naming the regions the shapes need that `mesh` lacks."""
    missing = [r for r in ARKIT_REGIONS if r not in mesh.regions]
    if missing:
        raise FacegenError(f"the face lacks the regions {', '.join(missing)} that the ARKit shapes are "
                           "built on: use facegen's procedural face (or a mesh of its topology with its "
                           "region files)")


def build_shapes(mesh: Mesh) -> Shapes:
    """The 52 shapes of `mesh`, built now (no cache): a face from facegen.face.procedural (its regions)."""
    from facegen.arkit.deformers import jaw_arc, shape_offsets
    from facegen.face.rig import Rig

    check_regions(mesh)
    rig = Rig(mesh)
    shapes = shape_offsets(rig, {k: np.asarray(v, np.int64) for k, v in mesh.regions.items()})
    return _frozen(np.stack([shapes[name] for name in ARKIT_NAMES]), rig.cm / 10.0, jaw_arc(rig)[None])


def arkit_shapes(mesh: Mesh) -> Shapes:
    """ARKit's 52 blend shapes on `mesh` (facegen's procedural face, any speaker): memoised in the process
    and cached on disk by the mesh's digest. FacegenError when the mesh lacks the regions they need."""
    key = mesh_digest(mesh)
    if key in _MEMO:
        return _MEMO[key]
    check_regions(mesh)
    path = cache_folder() / f"shapes-{key}.safetensors"
    shapes = _read(path, len(mesh.vertices)) if path.is_file() else None
    if shapes is None:
        shapes = build_shapes(mesh)
        _write(path, shapes)
    if len(_MEMO) >= _MEMO_SIZE:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[key] = shapes
    return shapes
