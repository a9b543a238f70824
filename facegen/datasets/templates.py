"""The community's templates.pkl ({subject: [V, 3] neutral face}), read without executing anything.

The file is a pickle; it is read with a restricted unpickler that accepts only dicts, strings and numpy
arrays (and the numpy functions that rebuild arrays): any other class or function is refused unloaded, and
no array is allocated before its shape and dtype are checked against the bytes the file holds for it.
"""

from __future__ import annotations

import io
import math
import os
import pickle
import re
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.errors import FacegenError
from facegen.input_files import read_input

MAX_PKL_BYTES = 64 << 20  # BIWI's is ~4 MB, VOCASET's ~1.5 MB


class _PickledArray:
    """What numpy's `_reconstruct` makes while a pickle is read: an empty placeholder that the pickle's BUILD
    gives the array's state (shape, dtype, bytes), which is checked before numpy makes the array from it."""

    def __init__(self, unpickler: _TemplateUnpickler) -> None:
        self.unpickler, self.array = unpickler, None

    def __setstate__(self, state) -> None:
        self.array = self.unpickler.array_from_state(state)


def _ndarray_called(*_args, **_kwargs):
    raise pickle.UnpicklingError("it calls numpy.ndarray directly, which makes an array of any size out of "
                                 "nothing (a memory bomb?)")


class _TemplateUnpickler(pickle._Unpickler):
    """Unpickles dicts, strings and numeric numpy arrays only; any other class or function is refused
    unloaded, and no array is made larger than the bytes of the file that are left for it (`budget`).

    The Python implementation of the unpickler: its memo is a dict, where the C one allocates a table as
    long as the largest memo index a pickle names (4 bytes of a file: 32 GB)."""

    def __init__(self, data: bytes) -> None:
        super().__init__(io.BytesIO(data), encoding="latin1")
        self.budget = len(data)
        try:
            from numpy._core import numeric
        except ImportError:  # numpy < 2
            from numpy.core import numeric  # type: ignore[no-redef]
        self._frombuffer = numeric._frombuffer
        self.allowed: dict[tuple[str, str], object] = {
            ("numpy", "ndarray"): _ndarray_called, ("numpy", "dtype"): _dtype, ("_codecs", "encode"): _latin1}
        for mod in ("numpy.core", "numpy._core"):
            self.allowed[(f"{mod}.multiarray", "_reconstruct")] = self.reconstruct
            self.allowed[(f"{mod}.numeric", "_frombuffer")] = self.frombuffer

    def find_class(self, module: str, name: str):
        fn = self.allowed.get((module, name))
        if fn is None:
            raise pickle.UnpicklingError(f"it names {module}.{name}, which is not a numpy array part")
        return fn

    def persistent_load(self, pid):
        raise pickle.UnpicklingError("it uses persistent ids")

    def reconstruct(self, subtype, shape, _dtype) -> _PickledArray:
        """numpy's pickles (protocols 0-4) make an empty ndarray first, then set its state (BUILD)."""
        if subtype is not _ndarray_called or tuple(np.atleast_1d(shape).tolist()) != (0,):
            raise pickle.UnpicklingError(f"it makes an array of shape {shape} out of nothing (a memory "
                                         "bomb?)")
        return _PickledArray(self)

    def array_from_state(self, state) -> np.ndarray:
        """numpy's ndarray.__setstate__ after the state's shape, dtype and bytes are checked."""
        if not isinstance(state, tuple) or len(state) not in (4, 5):
            raise pickle.UnpicklingError("an array's state is malformed")
        shape, dtype, _fortran, raw = state[-4:]
        if isinstance(raw, str):  # written by Python 2: bytes as latin-1 text
            raw = raw.encode("latin1")
        self._check(shape, dtype, raw)
        array = np.ndarray((0,), np.uint8)
        array.__setstate__(state[:-1] + (raw,))
        return array

    def frombuffer(self, buf, dtype, shape, order, axis_order=None) -> np.ndarray:
        """numpy's pickles of protocol 5: the array's bytes, then its dtype and shape."""
        self._check(shape, dtype, buf)
        if axis_order is None:
            return self._frombuffer(buf, dtype, shape, order)
        return self._frombuffer(buf, dtype, shape, order, axis_order)

    def _check(self, shape, dtype, raw) -> None:
        """Refuse a dtype that is not a plain number, a shape that is not a tuple of counts, and bytes that
        are not exactly what the shape needs or more than what is left of the file (sizes in Python integers:
        no overflow), before anything is allocated."""
        if not isinstance(dtype, np.dtype) or not _plain_number(dtype):
            raise pickle.UnpicklingError(f"it holds an array of dtype {dtype}, not a numeric numpy array")
        if (not isinstance(shape, tuple) or len(shape) > 32
                or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape)):
            raise pickle.UnpicklingError(f"an array's shape {shape!r} is not a tuple of sizes")
        nbytes = math.prod(shape) * dtype.itemsize
        if nbytes > self.budget:
            raise pickle.UnpicklingError(f"an array of shape {shape} {dtype} needs {nbytes:,} bytes, more "
                                         "than the file holds (a memory bomb?)")
        if not isinstance(raw, bytes | bytearray) or len(raw) != nbytes:
            got = len(raw) if isinstance(raw, bytes | bytearray) else type(raw).__name__
            raise pickle.UnpicklingError(f"an array of shape {shape} {dtype} comes with {got} bytes, not "
                                         f"{nbytes}")
        self.budget -= nbytes


def _plain_number(dtype: np.dtype) -> bool:
    return dtype.kind in "biuf" and dtype.fields is None and dtype.subdtype is None and not dtype.hasobject


def _dtype(obj, align=False, copy=False) -> np.dtype:
    """numpy.dtype for the names of plain numbers only ('f4', '<f8', 'i2', ...)."""
    if not isinstance(obj, str) or not re.fullmatch(r"[<>=|]?[biuf]\d{1,2}", obj):
        raise pickle.UnpicklingError(f"it makes a dtype of {obj!r}: not a numeric numpy array")
    return np.dtype(obj, align=bool(align), copy=bool(copy))


def _latin1(obj, encoding="utf-8") -> bytes:  # protocol-2 pickles store bytes as latin-1 text
    if not isinstance(obj, str) or encoding not in ("latin1", "latin-1"):
        raise pickle.UnpicklingError("_codecs.encode is allowed only for latin-1 text")
    return obj.encode("latin1")


def read_templates_pkl(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read the community's templates.pkl ({subject: [V, 3] array}) without executing anything.

    Only dicts, strings and numeric numpy arrays (and the numpy functions that rebuild arrays) are accepted,
    and no array larger than the file: anything else is refused with FacegenError before it is created.
    """
    path = Path(path)
    # from memory, not the file: a string opcode claiming 200 MB then reads only the bytes there are
    raw = read_input(path, what="templates file", limit=MAX_PKL_BYTES,
                     too_big="no set of face templates is that large (BIWI's is ~4 MB): check the file")
    try:
        data = _TemplateUnpickler(raw).load()
    except Exception as exc:  # UnpicklingError and whatever a malformed stream raises
        raise FacegenError(
            f"refusing to load {path}: {' '.join(str(exc).split())}; a templates.pkl may hold only a dict of "
            "numpy arrays (re-create it, or put the templates in templates/<subject>.npy)"
        ) from exc
    if not isinstance(data, dict):
        raise FacegenError(f"{path} holds a {type(data).__name__}, not a dict of templates: re-create it")
    out: dict[str, np.ndarray] = {}
    for key, value in data.items():
        value = value.array if isinstance(value, _PickledArray) else value
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
