"""USD values from Python: dictionary values (customLayerData) to and from plain Python (JSON-able values
become typed Vt arrays where a list holds one scalar type, else JSON strings; reading turns Vt arrays back
into lists), and one frame's points as a Vt.Vec3fArray (`vec3f_array`, the writers' hot path)."""

from __future__ import annotations

import ctypes
import json
from pathlib import Path

import numpy as np


def vec3f_array(points: np.ndarray):
    """`points` [N, 3] as a new Vt.Vec3fArray, copied at memory speed.

    usd-core's Vt.Vec3fArray.FromNumpy converts element by element (0.5 ms for a 23,370-point frame: 0.8 s of
    a minute's .usdc), so the values are copied into a new array's own storage through the address its
    read-only buffer view gives (a new VtArray owns its storage alone: the copy changes no other array)."""
    from pxr import Vt

    points = np.ascontiguousarray(points, np.float32)
    if points.ndim != 2 or points.shape[1] != 3 or not len(points):
        return Vt.Vec3fArray.FromNumpy(points)  # its own errors and the empty array
    out = Vt.Vec3fArray(len(points))
    view = np.asarray(out)
    address, _ = view.__array_interface__["data"]
    storage = (ctypes.c_float * points.size).from_address(address)
    np.ctypeslib.as_array(storage)[:] = points.reshape(-1)
    return out


def usd_dict(values: dict) -> dict:
    """The JSON-able part of a dict as USD dictionary values (lists become typed Vt arrays)."""
    out = {}
    for key, value in values.items():
        converted = usd_value(value)
        if converted is not None:
            out[str(key)] = converted
    return out


def usd_value(value):
    from pxr import Vt

    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, dict):
        return usd_dict(value)
    if isinstance(value, list | tuple | np.ndarray):
        items = [v.item() if isinstance(v, np.generic) else v for v in value]
        if items and all(isinstance(v, str) for v in items):
            return Vt.StringArray(items)
        if items and all(isinstance(v, int) and not isinstance(v, bool) for v in items):
            return Vt.Int64Array(items)
        if items and all(isinstance(v, int | float) and not isinstance(v, bool) for v in items):
            return Vt.DoubleArray([float(v) for v in items])
        try:
            return json.dumps(items)
        except (TypeError, ValueError):
            return None
    return None


def python_value(value):
    """USD dictionary values back to plain Python (Vt arrays become lists)."""
    if isinstance(value, dict):
        return {k: python_value(v) for k, v in value.items()}
    if isinstance(value, bool | int | float | str):
        return value
    try:
        return [python_value(v) for v in value]
    except TypeError:
        return str(value)
