"""Compare two folders of facegen outputs file by file: bytes first, else the values each kind of file holds.

Used by same_outputs.py (`compare DIR_A DIR_B`). Kinds: .npy arrays, USD stages (every prim, metadata,
attribute default and time samples, through pxr; .usdz too), glTF (the JSON and every accessor's values,
through pygltflib), WAV samples, JSON/CSV/TextGrid/text (numbers compared as numbers), pickles of arrays,
JUnit XML. Fields that legitimately differ from run to run are listed in IGNORED_* below, and nothing else is
ignored.
"""

from __future__ import annotations

import csv
import io
import json
import math
import pickle
import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

TOLERANCE = 1e-6  # vertex / weight values may differ by less than this (issue 21)
# Run-to-run fields, and nothing else: timings, dates, the host, absolute paths
IGNORED_JSON_KEYS = {"seconds", "elapsed", "elapsed_seconds", "wall", "wall_seconds", "duration_seconds",
                     "started", "finished", "date", "created", "timestamp", "time", "hostname", "host",
                     "pid", "load_average"}
IGNORED_XML_ATTRS = {"time", "timestamp", "hostname"}
IGNORED_JSON_KEYS |= {"worker_cpu_seconds", "cpu_seconds"}  # batch's report.json
IGNORED_TEXT = [re.compile(r"\bin \d+(\.\d+)? s\b"),  # "generated 2 sequences in 11 s" (synth, batch stdout)
                re.compile(r"\(\d+(\.\d+)?x real time\)")]  # batch's stdout
# stderr (progress, notes: not files written) and the tree run; evaluate's feature cache in the dataset folder
# (its keys and file names hold the files' mtimes)
NOT_OUTPUTS = ("logs/", "corpus/.facegen_cache/")
# Absolute paths (batch's report.json/.xml and stdout name OUTDIR): each folder's own path reads as <OUTDIR>.
# batch's .facegen-batch.json keeps [size, mtime_ns] per file: the mtime is dropped (drop_mtimes below).



class Diff:
    """What comparing two files found: the largest numeric difference and the first structural one."""

    def __init__(self, roots: tuple[str, str] = ("", "")) -> None:
        self.roots = roots  # each side's OUTDIR, read as <OUTDIR> in strings
        self.max_diff = 0.0
        self.where = ""
        self.problem: str | None = None

    def numbers(self, a: Any, b: Any, where: str) -> None:
        """Compare two numbers or numeric arrays of the same shape."""
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape:
            return self.fail(f"{where}: shape {a.shape} vs {b.shape}")
        if a.dtype.kind not in "biuf" or b.dtype.kind not in "biuf":
            if not np.array_equal(a, b):
                self.fail(f"{where}: {_short(a)} vs {_short(b)}")
            return None
        if a.size == 0:
            return None
        fa, fb = a.astype(np.float64), b.astype(np.float64)
        if not np.array_equal(np.isnan(fa), np.isnan(fb)):
            return self.fail(f"{where}: NaN in one only")
        ok = ~np.isnan(fa)
        if ok.any():
            d = float(np.max(np.abs(fa[ok] - fb[ok])))
            if d > self.max_diff:
                self.max_diff = d
                self.where = where
        return None

    def fail(self, problem: str) -> None:
        self.problem = self.problem or problem

    def value(self, a: Any, b: Any, where: str) -> None:
        """Compare parsed JSON-like values: numbers as numbers, the rest exactly, ignored keys skipped."""
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            return self.numbers(a, b, where)
        if isinstance(a, dict) and isinstance(b, dict):
            keys = (set(a) | set(b)) - IGNORED_JSON_KEYS
            for k in sorted(keys, key=str):
                if k not in a or k not in b:
                    self.fail(f"{where}.{k}: only in {'A' if k in a else 'B'}")
                else:
                    self.value(a[k], b[k], f"{where}.{k}")
        elif isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
            if len(a) != len(b):
                self.fail(f"{where}: {len(a)} vs {len(b)} items")
            elif a and all(_is_number(x) for x in a) and all(_is_number(x) for x in b):
                self.numbers(np.asarray(a, np.float64), np.asarray(b, np.float64), where)
            else:
                for i, (x, y) in enumerate(zip(a, b, strict=True)):
                    self.value(x, y, f"{where}[{i}]")
        elif _is_number(a) and _is_number(b):
            self.numbers(float(a), float(b), where)
        elif isinstance(a, str) and isinstance(b, str):
            if self._rooted(a, 0) != self._rooted(b, 1):
                self.fail(f"{where}: {_short(a)} vs {_short(b)}")
        elif a != b:
            self.fail(f"{where}: {_short(a)} vs {_short(b)}")
        return None

    def _rooted(self, s: str, side: int) -> str:
        return s.replace(self.roots[side], "<OUTDIR>") if self.roots[side] else s

    def text(self, a: str, b: str, where: str) -> None:
        """Compare text whose numbers are compared as numbers (TextGrid, stdout)."""
        a, b = self._rooted(a, 0), self._rooted(b, 1)
        for pattern in IGNORED_TEXT:
            a, b = pattern.sub("<ignored>", a), pattern.sub("<ignored>", b)
        number = r"(-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)"
        pa, pb = re.split(number, a), re.split(number, b)
        if len(pa) != len(pb):
            return self.fail(f"{where}: the text differs ({_first_line_diff(a, b)})")
        for i, (x, y) in enumerate(zip(pa, pb, strict=True)):
            if i % 2:
                self.numbers(float(x), float(y), where)
            elif x != y:
                return self.fail(f"{where}: the text differs ({_first_line_diff(a, b)})")
        return None


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float, np.number)) and not isinstance(x, bool)


def _short(x: Any) -> str:
    s = repr(x)
    return s if len(s) < 80 else s[:77] + "..."


def _first_line_diff(a: str, b: str) -> str:
    for i, (x, y) in enumerate(zip(a.splitlines(), b.splitlines(), strict=False)):
        if x != y:
            return f"line {i + 1}: {_short(x)} vs {_short(y)}"
    return f"{len(a.splitlines())} vs {len(b.splitlines())} lines"


def compare_npy(a: Path, b: Path, d: Diff) -> None:
    x, y = np.load(a, mmap_mode="r"), np.load(b, mmap_mode="r")
    if x.dtype != y.dtype:
        d.fail(f"dtype {x.dtype} vs {y.dtype}")
    d.numbers(x, y, "array")


def _usd_value(v: Any) -> Any:
    """A pxr value as something `Diff.value` compares: numeric Vt arrays and Gf types as numpy arrays."""
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    if isinstance(v, dict):
        return {str(k): _usd_value(x) for k, x in v.items()}
    try:
        arr = np.asarray(v)
        if arr.dtype.kind in "biuf":
            return arr
    except (TypeError, ValueError):
        pass
    if isinstance(v, (list, tuple)) or type(v).__name__.endswith("Array") or hasattr(v, "__len__"):
        try:
            return [_usd_value(x) for x in v]
        except TypeError:
            pass
    return str(v)


def _usd_compare_values(a: Any, b: Any, where: str, d: Diff) -> None:
    a, b = _usd_value(a), _usd_value(b)
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        d.numbers(a, b, where)
    else:
        d.value(a, b, where)


def compare_usd(a: Path, b: Path, d: Diff) -> None:
    """Every prim: its type and metadata, each attribute's default and time samples, relationship targets."""
    from pxr import Usd

    sa, sb = Usd.Stage.Open(str(a)), Usd.Stage.Open(str(b))
    prims_a = {str(p.GetPath()): p for p in [sa.GetPseudoRoot(), *sa.TraverseAll()]}
    prims_b = {str(p.GetPath()): p for p in [sb.GetPseudoRoot(), *sb.TraverseAll()]}
    if set(prims_a) != set(prims_b):
        return d.fail(f"prims differ: {sorted(set(prims_a) ^ set(prims_b))[:5]}")
    for path, pa in prims_a.items():
        pb = prims_b[path]
        if pa.GetTypeName() != pb.GetTypeName():
            d.fail(f"{path}: type {pa.GetTypeName()} vs {pb.GetTypeName()}")
        _usd_compare_values(pa.GetAllMetadata(), pb.GetAllMetadata(), f"{path} metadata", d)
        names_a, names_b = set(pa.GetPropertyNames()), set(pb.GetPropertyNames())
        if names_a != names_b:
            d.fail(f"{path}: properties {sorted(names_a ^ names_b)}")
        for name in sorted(names_a & names_b):
            xa, xb = pa.GetProperty(name), pb.GetProperty(name)
            where = f"{path}.{name}"
            if hasattr(xa, "GetTargets"):
                if [str(t) for t in xa.GetTargets()] != [str(t) for t in xb.GetTargets()]:
                    d.fail(f"{where}: targets differ")
                continue
            _usd_compare_values(xa.GetAllMetadata(), xb.GetAllMetadata(), f"{where} metadata", d)
            times_a, times_b = xa.GetTimeSamples(), xb.GetTimeSamples()
            if list(times_a) != list(times_b):
                d.fail(f"{where}: {len(times_a)} vs {len(times_b)} time samples")
                continue
            _usd_compare_values(xa.Get(), xb.Get(), where, d)
            for t in times_a:
                _usd_compare_values(xa.Get(t), xb.Get(t), f"{where}@{t:g}", d)
    return None


def compare_usdz(a: Path, b: Path, d: Diff) -> None:
    """The package's members (names, and the bytes of the non-USD ones) and its composed stage."""
    with zipfile.ZipFile(a) as za, zipfile.ZipFile(b) as zb:
        if za.namelist() != zb.namelist():
            d.fail(f"members {za.namelist()} vs {zb.namelist()}")
        for name in set(za.namelist()) & set(zb.namelist()):
            if not name.endswith((".usdc", ".usda", ".usd")) and za.read(name) != zb.read(name):
                d.fail(f"member {name} differs")
    compare_usd(a, b, d)


def _gltf_arrays(path: Path) -> tuple[dict, list[np.ndarray]]:
    """A glTF's JSON (as a dict) and each accessor's values."""
    import base64

    import pygltflib

    g = pygltflib.GLTF2().load(str(path))
    blobs = []
    for i, buf in enumerate(g.buffers):
        if buf.uri is None:
            blobs.append(g.binary_blob())
        elif buf.uri.startswith("data:"):
            blobs.append(base64.b64decode(buf.uri.split(",", 1)[1]))
        else:
            blobs.append((path.parent / buf.uri).read_bytes())
        del i
    kinds = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
    sizes = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
    arrays = []
    for acc in g.accessors:
        n = sizes[acc.type]
        if acc.bufferView is None:
            arrays.append(np.zeros((acc.count, n), kinds[acc.componentType]))
            continue
        view = g.bufferViews[acc.bufferView]
        dtype = np.dtype(kinds[acc.componentType])
        stride = view.byteStride or dtype.itemsize * n
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        raw = np.frombuffer(blobs[view.buffer], np.uint8, count=stride * (acc.count - 1) + dtype.itemsize * n,
                            offset=start)
        rows = np.lib.stride_tricks.as_strided(raw, (acc.count, dtype.itemsize * n), (stride, 1))
        arrays.append(np.ascontiguousarray(rows).view(dtype).reshape(acc.count, n))
    doc = json.loads(g.to_json())
    return doc, arrays


def compare_gltf(a: Path, b: Path, d: Diff) -> None:
    """The JSON without the byte layout (buffers, views, offsets) plus every accessor's values."""
    ja, arrays_a = _gltf_arrays(a)
    jb, arrays_b = _gltf_arrays(b)
    for doc in (ja, jb):
        doc.pop("buffers", None)
        doc.pop("bufferViews", None)
        for acc in doc.get("accessors", []):
            acc.pop("bufferView", None)
            acc.pop("byteOffset", None)
    d.value(ja, jb, "json")
    if len(arrays_a) == len(arrays_b):
        for i, (x, y) in enumerate(zip(arrays_a, arrays_b, strict=True)):
            d.numbers(x, y, f"accessor {i}")


def compare_wav(a: Path, b: Path, d: Diff) -> None:
    import soundfile as sf

    (x, ra), (y, rb) = sf.read(a, dtype="float64"), sf.read(b, dtype="float64")
    if ra != rb or sf.info(a).subtype != sf.info(b).subtype:
        d.fail(f"rate/subtype {ra} {sf.info(a).subtype} vs {rb} {sf.info(b).subtype}")
    d.numbers(x, y, "samples")


def compare_csv(a: Path, b: Path, d: Diff) -> None:
    def rows(path: Path) -> list[list[float | str]]:
        return [[_number_or_text(c) for c in r] for r in csv.reader(io.StringIO(path.read_text()))]

    d.value(rows(a), rows(b), "rows")


def _number_or_text(cell: str) -> float | str:
    try:
        x = float(cell)
    except ValueError:
        return cell
    return x if math.isfinite(x) else cell


def compare_xml(a: Path, b: Path, d: Diff) -> None:
    import xml.etree.ElementTree as ET

    def tree(e: ET.Element) -> dict:
        attrs = {k: _number_or_text(v) for k, v in e.attrib.items() if k not in IGNORED_XML_ATTRS}
        return {"tag": e.tag, "attrs": attrs, "text": (e.text or "").strip(),
                "children": [tree(c) for c in e]}

    d.value(tree(ET.parse(a).getroot()), tree(ET.parse(b).getroot()), "xml")


def compare_pickle(a: Path, b: Path, d: Diff) -> None:
    with open(a, "rb") as fa, open(b, "rb") as fb:
        x, y = pickle.load(fa), pickle.load(fb)  # our own outputs

    def plain(v: Any) -> Any:
        if isinstance(v, dict):
            return {str(k): plain(w) for k, w in v.items()}
        return np.asarray(v) if isinstance(v, np.ndarray) or _is_number(v) else v

    pa, pb = plain(x), plain(y)
    if isinstance(pa, dict) and isinstance(pb, dict) and set(pa) == set(pb):
        for k in sorted(pa):
            _usd_compare_values(pa[k], pb[k], k, d)
    else:
        d.value(pa, pb, "pickle")


def drop_mtimes(state: dict) -> dict:
    """batch's .facegen-batch.json without the files' mtimes: {"items": {name: {"files": {f: [size, mtime]}}}}
    keeps [size]."""
    for item in state.get("items", {}).values():
        item["files"] = {k: v[:1] for k, v in item.get("files", {}).items()}
    return state


def compare_file(a: Path, b: Path, roots: tuple[str, str] = ("", "")) -> Diff:
    """Compare two files by kind (see the module docstring)."""
    d = Diff(roots)
    suffix = a.suffix.lower()
    try:
        if suffix == ".npy":
            compare_npy(a, b, d)
        elif suffix in (".usda", ".usdc", ".usd"):
            compare_usd(a, b, d)
        elif suffix == ".usdz":
            compare_usdz(a, b, d)
        elif suffix in (".glb", ".gltf"):
            compare_gltf(a, b, d)
        elif suffix == ".wav":
            compare_wav(a, b, d)
        elif suffix == ".json":
            ja, jb = json.loads(a.read_text()), json.loads(b.read_text())
            if a.name == ".facegen-batch.json":
                ja, jb = drop_mtimes(ja), drop_mtimes(jb)
            d.value(ja, jb, "json")
        elif suffix == ".csv":
            compare_csv(a, b, d)
        elif suffix == ".xml":
            compare_xml(a, b, d)
        elif suffix == ".pkl":
            compare_pickle(a, b, d)
        elif suffix in (".txt", ".textgrid", ""):
            d.text(a.read_text(), b.read_text(), "text")
        else:
            d.fail("bytes differ (no value comparison for this kind of file)")
    except Exception as exc:  # noqa: BLE001 (a file that does not parse is a difference, named)
        d.fail(f"cannot compare: {type(exc).__name__}: {exc}")
    return d


def files(root: Path) -> set[str]:
    """The files under `root` that are outputs (relative POSIX paths)."""
    return {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()
            and not p.relative_to(root).as_posix().startswith(NOT_OUTPUTS)}


def compare(a_root: Path, b_root: Path) -> int:
    """Print one line per file; returns the number of files that differ."""
    fa, fb = files(a_root), files(b_root)
    different = 0
    for rel in sorted(fa | fb):
        if rel not in fb or rel not in fa:
            print(f"{rel}: DIFFERENT: only in {'A' if rel in fa else 'B'}")
            different += 1
            continue
        a, b = a_root / rel, b_root / rel
        if a.stat().st_size == b.stat().st_size and _same_bytes(a, b):
            print(f"{rel}: identical")
            continue
        d = compare_file(a, b, (str(a_root.resolve()), str(b_root.resolve())))
        if d.problem:
            print(f"{rel}: DIFFERENT: {d.problem}")
            different += 1
        elif d.max_diff > TOLERANCE:
            print(f"{rel}: DIFFERENT: max diff {d.max_diff:.3g} > {TOLERANCE:g} (at {d.where})")
            different += 1
        else:
            at = f" at {d.where}" if d.max_diff else ""
            print(f"{rel}: same values, bytes differ (max diff {d.max_diff:.3g}{at})")
    print(f"{len(fa | fb)} files, {different} DIFFERENT")
    return different


def _same_bytes(a: Path, b: Path) -> bool:
    with open(a, "rb") as fa, open(b, "rb") as fb:
        while True:
            x, y = fa.read(1 << 20), fb.read(1 << 20)
            if x != y:
                return False
            if not x:
                return True
