"""USD dictionary values (customLayerData) to and from plain Python: JSON-able values become typed Vt arrays
where a list holds one scalar type, else JSON strings; reading turns Vt arrays back into lists."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


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
