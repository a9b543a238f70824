"""Template meshes: read/write PLY and OBJ, vertex regions, topology fingerprint, area, normalisation, normals."""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facegen.errors import FacegenError


@dataclass
class Mesh:
    """A fixed-topology triangle mesh: vertices [V, 3] float32, faces [F, 3] int32, named regions."""

    vertices: np.ndarray
    faces: np.ndarray
    regions: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def num_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def size(self) -> float:
        """The face's size: the diagonal of its bounding box (the unit for relative tolerances)."""
        return float(np.linalg.norm(self.vertices.max(0) - self.vertices.min(0)))

    def fingerprint(self) -> str:
        return topology_fingerprint(self.num_vertices, self.faces)


def topology_fingerprint(num_vertices: int, faces: np.ndarray) -> str:
    """A short hash of the vertex count and face list: equal iff the topology is equal."""
    h = hashlib.sha256()
    h.update(str(int(num_vertices)).encode())
    h.update(np.ascontiguousarray(faces, dtype=np.int32).tobytes())
    return h.hexdigest()[:16]


def read_mesh(path: str | os.PathLike) -> Mesh:
    """Read a PLY or OBJ mesh exactly as stored (no vertex merging or reordering)."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise FacegenError(f"mesh file {path} does not exist: pass an existing .ply or .obj file")
    if path.suffix.lower() not in (".ply", ".obj"):
        raise FacegenError(f"mesh file {path} is not .ply or .obj: convert it to PLY or OBJ")
    try:
        tm = trimesh.load(path, process=False, force="mesh", maintain_order=True)
    except Exception as exc:  # trimesh raises many types for bad files
        raise FacegenError(f"cannot read mesh {path} ({exc}): pass a valid PLY or OBJ file") from exc
    vertices = np.asarray(tm.vertices, dtype=np.float32)
    faces = np.asarray(tm.faces, dtype=np.int32)
    if vertices.ndim != 2 or vertices.shape[0] == 0 or faces.ndim != 2 or faces.shape[0] == 0:
        raise FacegenError(f"mesh {path} has no vertices or no triangles: pass a triangle mesh")
    if not np.isfinite(vertices).all():
        raise FacegenError(f"mesh {path} has NaN or infinite vertex coordinates: fix or re-export it")
    return Mesh(vertices, faces)


def write_mesh(mesh: Mesh, path: str | os.PathLike) -> None:
    """Write a PLY (binary) or OBJ file, keeping the vertex order."""
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    tm.export(str(path))


def read_region(path: str | os.PathLike) -> np.ndarray:
    """Read a region file: 0-based vertex indices separated by commas and/or whitespace."""
    text = Path(path).read_text()
    try:
        values = [int(tok) for tok in text.replace(",", " ").split()]
    except ValueError as exc:
        raise FacegenError(f"region file {path} is not a list of vertex indices: {exc}") from exc
    return np.asarray(values, dtype=np.int64)


def write_region(indices: np.ndarray, path: str | os.PathLike) -> None:
    """Write a region file in the community's format: one line, indices joined by ', '."""
    Path(path).write_text(", ".join(str(int(i)) for i in indices) + "\n")


def check_topology(mesh: Mesh, num_vertices: int, faces: np.ndarray, what: str) -> None:
    """Refuse a mesh whose vertex count or face list differs from the expected topology."""
    if mesh.num_vertices != num_vertices:
        raise FacegenError(
            f"{what} has {mesh.num_vertices} vertices but the model expects {num_vertices}: "
            "use a mesh with the model's topology"
        )
    if mesh.faces.shape != faces.shape or not np.array_equal(mesh.faces, faces):
        raise FacegenError(
            f"{what} has the right vertex count but a different face list ({mesh.faces.shape[0]} faces, "
            f"model has {faces.shape[0]}): use a mesh with the model's topology"
        )


def surface_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Total triangle area (the community's sum of mixed-Voronoi vertex areas equals it)."""
    v = np.asarray(vertices, np.float64)
    e1 = v[faces[:, 1]] - v[faces[:, 0]]
    e2 = v[faces[:, 2]] - v[faces[:, 0]]
    return float(0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum())


def unit_area(vertices: np.ndarray, faces: np.ndarray,
              reference: tuple[np.ndarray, float] | None = None) -> np.ndarray:
    """BIWI's normalisation: subtract the mean vertex, divide by the square root of the surface area
    (float64 out). With `reference` = (mean, sqrt_area), that centre and scale are used instead."""
    v = np.asarray(vertices, np.float64)
    if reference is None:
        v = v - v.mean(axis=0)
        return v / np.sqrt(surface_area(v, faces))
    mean, scale = reference
    return (v - mean) / scale


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (+Z for a vertex in no or only degenerate triangles)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    face_normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    normals = np.zeros_like(v)
    for corner in range(3):
        np.add.at(normals, f[:, corner], face_normals)
    length = np.linalg.norm(normals, axis=1)
    bad = length < 1e-20
    normals[bad] = (0.0, 0.0, 1.0)
    length[bad] = 1.0
    return (normals / length[:, None]).astype(np.float32)
