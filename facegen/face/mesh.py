"""Template meshes: read/write PLY and OBJ, vertex regions, topology fingerprint, area, normalisation,
normals."""

from __future__ import annotations

import functools
import hashlib
import math
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


def vertex_normals(vertices: np.ndarray, faces: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Area-weighted unit vertex normals [V, 3] float32 (+Z for a vertex in no or only degenerate triangles).

    Summed in float64 unless `out` is given: a float32 [V, 3] buffer that receives float32 sums, the
    renderer's per frame (~1 ms for BIWI's 46,068 triangles, 40x numpy's np.add.at)."""
    if out is not None:
        _normals_kernel()(np.ascontiguousarray(vertices, out.dtype), np.ascontiguousarray(faces), out)
        return out
    v = np.ascontiguousarray(vertices, np.float64)
    normals = np.empty_like(v)
    _normals_kernel()(v, np.ascontiguousarray(faces), normals)
    return normals.astype(np.float32)


@functools.cache
def _normals_kernel():
    """The numba kernel, compiled (or loaded from numba's cache) on first use: numba loads only if needed."""
    import numba

    @numba.njit(cache=True, nogil=True, fastmath=True)
    def normals_into(vertices: np.ndarray, faces: np.ndarray, out: np.ndarray) -> None:
        out[:] = 0.0
        for f in range(faces.shape[0]):
            a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
            ux = vertices[b, 0] - vertices[a, 0]
            uy = vertices[b, 1] - vertices[a, 1]
            uz = vertices[b, 2] - vertices[a, 2]
            vx = vertices[c, 0] - vertices[a, 0]
            vy = vertices[c, 1] - vertices[a, 1]
            vz = vertices[c, 2] - vertices[a, 2]
            nx = uy * vz - uz * vy
            ny = uz * vx - ux * vz
            nz = ux * vy - uy * vx
            for k in (a, b, c):
                out[k, 0] += nx
                out[k, 1] += ny
                out[k, 2] += nz
        # the +Z pass is a loop of its own and the division keeps its `n > 0.0` guard: changing how the
        # loop below is written changes numba's float32 code, and with it some of the renderer's pixels
        for i in range(out.shape[0]):
            if out[i, 0] ** 2 + out[i, 1] ** 2 + out[i, 2] ** 2 < 1e-40:  # no area: +Z
                out[i, 0], out[i, 1], out[i, 2] = 0.0, 0.0, 1.0
        for i in range(out.shape[0]):
            n = math.sqrt(out[i, 0] ** 2 + out[i, 1] ** 2 + out[i, 2] ** 2)
            if n > 0.0:
                out[i, 0] /= n
                out[i, 1] /= n
                out[i, 2] /= n

    return normals_into
