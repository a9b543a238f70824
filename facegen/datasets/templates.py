"""The community's templates.pkl ({subject: [V, 3] neutral face}), read without executing anything.

The file is a pickle; it is read with a restricted unpickler that accepts only dicts, strings and numpy
arrays (and the numpy functions that rebuild arrays): any other class or function is refused unloaded.
"""

from __future__ import annotations

import io
import os
import pickle
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.errors import FacegenError

MAX_PKL_BYTES = 256 << 20


def _allowed_globals() -> dict[tuple[str, str], object]:
    """The only callables a templates.pkl may name: what pickled numpy arrays need, nothing else."""
    try:
        from numpy._core import multiarray, numeric
    except ImportError:  # numpy < 2
        from numpy.core import multiarray, numeric  # type: ignore[no-redef]

    def latin1_encode(obj, encoding="utf-8"):  # protocol-2 pickles store bytes as latin-1 text
        if not isinstance(obj, str) or encoding not in ("latin1", "latin-1"):
            raise pickle.UnpicklingError("_codecs.encode is allowed only for latin-1 text")
        return obj.encode("latin1")

    def empty_reconstruct(subtype, shape, dtype):  # numpy pickles an empty array, then fills it from the file
        if tuple(np.atleast_1d(shape)) != (0,):
            raise pickle.UnpicklingError(f"it makes an array of shape {shape} out of nothing (a memory "
                                         "bomb?)")
        return multiarray._reconstruct(subtype, shape, dtype)

    allowed: dict[tuple[str, str], object] = {("numpy", "ndarray"): np.ndarray, ("numpy", "dtype"): np.dtype,
                                              ("_codecs", "encode"): latin1_encode}
    for mod in ("numpy.core", "numpy._core"):
        allowed[(f"{mod}.multiarray", "_reconstruct")] = empty_reconstruct
        allowed[(f"{mod}.numeric", "_frombuffer")] = numeric._frombuffer
    return allowed


class _TemplateUnpickler(pickle.Unpickler):
    """Unpickles dicts, strings and numpy arrays only; any other class or function is refused unloaded."""

    def find_class(self, module: str, name: str):
        fn = _allowed_globals().get((module, name))
        if fn is None:
            raise pickle.UnpicklingError(f"it names {module}.{name}, which is not a numpy array part")
        return fn

    def persistent_load(self, pid):
        raise pickle.UnpicklingError("it uses persistent ids")


def read_templates_pkl(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read the community's templates.pkl ({subject: [V, 3] array}) without executing anything.

    Only dicts, strings and numpy arrays (and the numpy functions that rebuild arrays) are accepted;
    anything else is refused with FacegenError before it is created.
    """
    path = Path(path)
    if path.is_file() and path.stat().st_size > MAX_PKL_BYTES:
        raise FacegenError(f"{path} is {path.stat().st_size / 1e6:.0f} MB, more than any set of face "
                           "templates (BIWI's is ~4 MB): check the file")
    try:
        # from memory, not the file: a string opcode claiming 200 MB then reads only the bytes there are
        data = _TemplateUnpickler(io.BytesIO(path.read_bytes()), encoding="latin1").load()
    except OSError as exc:
        raise FacegenError(f"cannot read {path} ({exc.strerror}): check the file") from exc
    except Exception as exc:  # UnpicklingError and whatever a malformed stream raises
        raise FacegenError(
            f"refusing to load {path}: {exc}; a templates.pkl may hold only a dict of numpy arrays "
            "(re-create it, or put the templates in templates/<subject>.npy)"
        ) from exc
    if not isinstance(data, dict):
        raise FacegenError(f"{path} holds a {type(data).__name__}, not a dict of templates: re-create it")
    out: dict[str, np.ndarray] = {}
    for key, value in data.items():
        if not isinstance(key, str) or not isinstance(value, np.ndarray) or value.dtype.kind not in "fiu":
            raise FacegenError(f"{path}: entry {key!r} is not a numeric numpy array: re-create the file")
        out[key] = as_vertices(value, f"{path} entry {key!r}")
    return out


def as_vertices(value: np.ndarray, what: str) -> np.ndarray:
    """A template as contiguous float32 [V, 3] ([3V] accepted), refused when empty or not finite."""
    v = np.asarray(value, dtype=np.float32)
    if v.ndim == 1 and v.size % 3 == 0:
        v = v.reshape(-1, 3)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
        raise FacegenError(f"{what} has shape {value.shape}, not [V, 3]: re-create it")
    if not np.isfinite(v).all():
        raise FacegenError(f"{what} has NaN or infinite coordinates: re-create it")
    return np.ascontiguousarray(v)


def write_templates_pkl(templates: dict[str, np.ndarray], path: str | os.PathLike) -> None:
    """Write {subject: [V, 3] float32} as the community's templates.pkl (readable by read_templates_pkl)."""
    data = {str(k): np.ascontiguousarray(v, np.float32) for k, v in templates.items()}
    with atomic_path(path) as tmp:
        tmp.write_bytes(pickle.dumps(data, protocol=4))
