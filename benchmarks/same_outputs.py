"""Same outputs: run a fixed set of facegen commands with one source tree; compare two such runs file by file.

A refactoring that must change no output (issue 21) is checked against a baseline commit like this:

    git worktree add /tmp/baseline 0dc2807
    python benchmarks/same_outputs.py run /tmp/baseline /tmp/base_out
    python benchmarks/same_outputs.py run . /tmp/head_out
    python benchmarks/same_outputs.py compare /tmp/base_out /tmp/head_out

`run SRC_TREE OUTDIR` writes the fixed inputs into OUTDIR/inputs (taken from commit INPUTS_COMMIT with git, so
that both runs read the same bytes whatever the trees moved), then runs every command of `commands()` as
`python -m facegen ...` in a new process with PYTHONPATH=SRC_TREE and OUTDIR as the working folder (relative
paths only: no absolute path lands in an output). Each command's stdout is kept in OUTDIR/stdout/NAME.txt (an
output too), its exit code and wall seconds in OUTDIR/run.json; its stderr (progress and notes, not an output)
in OUTDIR/logs/NAME.stderr, the tree and its commit in OUTDIR/logs/tree.json.

`compare DIR_A DIR_B` compares every file of the two folders (logs/ aside): byte-identical first; else by
kind: .npy arrays, USD stages (every prim, metadata, attribute default and time samples, through pxr; .usdz
too), glTF (the JSON and every accessor's values, through pygltflib), WAV samples, JSON/CSV/TextGrid/text
(numbers compared as numbers), pickles of arrays, JUnit XML. One line per file: `identical`, `same values
(max diff X)` when every number is within TOLERANCE, or `DIFFERENT: why`. Exit status 1 when a file differs.
Fields that legitimately differ from run to run are listed in IGNORED_* below, and nothing else is ignored.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import os
import pickle
import re
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
INPUTS_COMMIT = "0dc2807"  # the inputs' bytes come from this commit (git show), whichever tree runs
TOLERANCE = 1e-6  # vertex / weight values may differ by less than this (issue 21)
# Run-to-run fields, and nothing else: timings, dates, the host, absolute paths
IGNORED_JSON_KEYS = {"seconds", "elapsed", "elapsed_seconds", "wall", "wall_seconds", "duration_seconds",
                     "started", "finished", "date", "created", "timestamp", "time", "hostname", "host",
                     "pid", "load_average"}
IGNORED_XML_ATTRS = {"time", "timestamp", "hostname"}
IGNORED_TEXT = [re.compile(r"\bin \d+(\.\d+)? s\b")]  # "generated 2 sequences in 11 s" (data synth's stdout)
NOT_OUTPUTS = ("logs/",)  # stderr (progress, notes: not files written), the tree run

# the clip's words and phones (as `facegen align --phones` found them at 0dc2807): the --alignment input
WORDS = ("What 0 0.24, an 0.24 0.34, excellent 0.34 0.9, room 0.9 1.14, you 1.14 1.28, have 1.28 1.7, "
         "sir 1.88 2.29, Such 2.63 2.92, expensive 2.92 3.61, furnishings 3.61 4.38")
PHONES = ("W 0 0.09, AH 0.09 0.14, T 0.14 0.24, AH 0.24 0.28, N 0.28 0.34, EH 0.34 0.43, K 0.43 0.51, "
          "S 0.51 0.6, AH 0.6 0.64, L 0.64 0.7, AH 0.7 0.73, N 0.73 0.8, T 0.8 0.9, R 0.9 0.94, "
          "UW 0.94 1.11, M 1.11 1.14, Y 1.14 1.19, UW 1.19 1.28, HH 1.28 1.34, AE 1.34 1.59, "
          "V 1.59 1.7, S 1.88 1.99, ER 1.99 2.29, S 2.63 2.71, AH 2.71 2.83, CH 2.83 2.92, "
          "EH 2.92 2.99, K 2.99 3.1, S 3.1 3.15, P 3.15 3.19, EH 3.19 3.29, N 3.29 3.38, S 3.38 3.46, "
          "IH 3.46 3.53, V 3.53 3.61, F 3.61 3.7, ER 3.7 3.88, N 3.88 3.92, IH 3.92 3.98, "
          "SH 3.98 4.08, IH 4.08 4.16, NG 4.16 4.28, Z 4.28 4.38")
MANIFEST = """audio,text,text_file,alignment,speaker,output
room.wav,"What an excellent room you have, sir. Such expensive furnishings!",,,F3,b1.npy
room.wav,,room.txt,,,b2.npy
room.wav,,,words.json,M4,b3.npy
"""  # paths relative to the manifest's folder (inputs/), outputs to --output-dir
FOLDERS = {"batch": "batch", "data_synth": "corpus"}  # the folders these commands write into
SPLIT = ["--train-subjects", "F2", "--test-subjects", "F1", "--train-sentences", "1-30", "--val-sentences",
         "31-36", "--test-sentences", "37-38"]


# --------------------------------------------------------------------------------------------------
# run


def commands() -> list[tuple[str, list[str]]]:
    """The fixed commands: (name, arguments after `python -m facegen`), run in this order in OUTDIR."""
    room = ["inputs/room.wav", "--text-file", "inputs/room.txt", "-q"]
    cmds = [(f"animate_{ext}", ["animate", *room, "-o", f"anim/points.{ext}"])
            for ext in ("usda", "usdc", "usdz", "glb", "gltf", "npy", "json", "csv")]
    cmds += [
        ("animate_blendshapes", ["animate", *room, "--usd-mode", "blendshapes", "-o", "anim/blend.usda"]),
        ("animate_arkit_usdc", ["animate", *room, "--rig", "arkit", "-o", "anim/arkit.usdc"]),
        ("animate_arkit_glb", ["animate", *room, "--rig", "arkit", "-o", "anim/arkit.glb"]),
        ("animate_morph8", ["animate", *room, "--morph-targets", "8", "-o", "anim/morph8.glb"]),
        ("animate_speaker", ["animate", *room, "--speaker", "M3", "-o", "anim/speaker.npy"]),
        ("animate_no_text", ["animate", "inputs/room.wav", "--no-text", "-q", "-o", "anim/no_text.npy"]),
        ("animate_alignment", ["animate", "inputs/room.wav", "--alignment", "inputs/words.json", "-q",
                               "-o", "anim/alignment.npy"]),
        ("animate_template", ["animate", *room, "--template", "inputs/wide_face.ply",
                              "-o", "anim/template.npy"]),
        ("validate", ["validate", "anim/points.usdc", "--json"]),
        ("align_json", ["align", "inputs/room.wav", "--text-file", "inputs/room.txt", "--phones",
                        "-o", "align/words.json"]),
        ("align_textgrid", ["align", "inputs/room.wav", "--text-file", "inputs/room.txt", "--phones",
                            "-o", "align/words.TextGrid"]),
        ("batch", ["batch", "inputs/lines.csv", "-o", "batch", "--jobs", "1", "--formats", "npy,glb", "-q"]),
        ("data_synth", ["data", "synth", "corpus", "--subjects", "F2", "--sentences", "37-38",
                        "--workers", "1", "-q"]),
        ("evaluate", ["evaluate", "inputs/default.safetensors", "corpus", "--split", "test-a", *SPLIT,
                      "--json", "-q"]),
    ]
    return cmds


def git_bytes(path: str) -> bytes:
    """The bytes of `path` at INPUTS_COMMIT."""
    return subprocess.run(["git", "-C", str(REPO), "show", f"{INPUTS_COMMIT}:{path}"], capture_output=True,
                          check=True).stdout


def wide_face(ply: bytes) -> bytes:
    """The procedural face's binary PLY with its vertices 5 % wider and 2 % taller (a --template input)."""
    end = ply.index(b"end_header\n") + len(b"end_header\n")
    count = int(re.search(rb"element vertex (\d+)", ply[:end]).group(1))
    vertices = np.frombuffer(ply[end:end + 12 * count], "<f4").reshape(count, 3)
    vertices = vertices * np.float32([1.05, 1.02, 1.0])
    return ply[:end] + vertices.astype("<f4").tobytes() + ply[end + 12 * count:]


def words_json() -> dict:
    """WORDS and PHONES as facegen's plain JSON alignment."""
    def rows(table: str, key: str) -> list[dict]:
        cells = (row.split() for row in table.split(", "))
        return [{key: x, "start": float(a), "end": float(b)} for x, a, b in cells]

    return {"words": rows(WORDS, "word"), "phones": rows(PHONES, "phone")}


def write_inputs(folder: Path) -> None:
    """The commands' inputs, the same bytes for every tree."""
    folder.mkdir(parents=True)
    (folder / "room.wav").write_bytes(git_bytes("examples/excellent_room.wav"))
    (folder / "room.txt").write_bytes(git_bytes("examples/excellent_room.txt"))
    (folder / "default.safetensors").write_bytes(git_bytes("facegen/models/default.safetensors"))
    (folder / "wide_face.ply").write_bytes(wide_face(git_bytes("templates/face.ply")))
    (folder / "words.json").write_text(json.dumps(words_json(), indent=1) + "\n")
    (folder / "lines.csv").write_text(MANIFEST)


def run(tree: Path, out: Path, only: list[str] | None = None) -> int:
    """Run the commands with `tree`'s facegen into the new folder `out`; returns how many failed."""
    tree = tree.resolve()
    if out.exists() and not only:
        raise SystemExit(f"{out} exists: give a new folder (or --only NAME... to redo some commands in it)")
    if not (out / "inputs").is_dir():
        write_inputs(out / "inputs")
    for sub in ("stdout", "logs", "anim", "align"):
        (out / sub).mkdir(exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(tree), HF_HUB_OFFLINE="1", TRANSFORMERS_OFFLINE="1")
    check = subprocess.run([sys.executable, "-c", "import facegen; print(facegen.__file__)"], cwd=out,
                           env=env, capture_output=True, text=True, check=True).stdout.strip()
    if not Path(check).resolve().is_relative_to(tree):
        raise SystemExit(f"PYTHONPATH={tree} does not win: facegen is imported from {check}")
    (out / "logs" / "tree.json").write_text(json.dumps({"tree": str(tree), "commit": _commit(tree)}) + "\n")
    record: dict[str, Any] = {"commands": {}}
    if only and (out / "run.json").is_file():
        record = json.loads((out / "run.json").read_text())
    failed = 0
    for name, args in commands():
        if only and name not in only:
            continue
        if name in FOLDERS:  # a new folder, as on a first run (batch and synth skip what is there)
            shutil.rmtree(out / FOLDERS[name], ignore_errors=True)
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "facegen", *args], cwd=out, env=env, capture_output=True,
                              text=True, check=False)
        seconds = time.perf_counter() - t0
        (out / "stdout" / f"{name}.txt").write_text(proc.stdout)
        (out / "logs" / f"{name}.stderr").write_text(proc.stderr)
        record["commands"][name] = {"args": args, "returncode": proc.returncode, "seconds": round(seconds, 2)}
        failed += proc.returncode != 0
        error = f"  {proc.stderr.strip()[-300:]}" if proc.returncode else ""
        print(f"{name:22s} exit {proc.returncode}  {seconds:5.1f} s{error}", flush=True)
    (out / "run.json").write_text(json.dumps(record, indent=1) + "\n")
    return failed


def _commit(tree: Path) -> str:
    proc = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True, check=False)
    return proc.stdout.strip()


# --------------------------------------------------------------------------------------------------
# compare


class Diff:
    """What comparing two files found: the largest numeric difference and the first structural one."""

    def __init__(self) -> None:
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
        elif a != b:
            self.fail(f"{where}: {_short(a)} vs {_short(b)}")
        return None

    def text(self, a: str, b: str, where: str) -> None:
        """Compare text whose numbers are compared as numbers (TextGrid, stdout)."""
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


def compare_file(a: Path, b: Path, rel: str) -> Diff:
    """Compare two files by kind (see the module docstring)."""
    d = Diff()
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
            d.value(json.loads(a.read_text()), json.loads(b.read_text()), "json")
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
    del rel
    return d


def files(root: Path) -> set[str]:
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
        d = compare_file(a, b, rel)
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the fixed commands with SRC_TREE's facegen into OUTDIR")
    r.add_argument("tree", type=Path, metavar="SRC_TREE")
    r.add_argument("out", type=Path, metavar="OUTDIR")
    r.add_argument("--only", nargs="*", help="only these commands (names as printed), into OUTDIR as it is")
    r.add_argument("--replace", action="store_true", help="delete OUTDIR first")
    c = sub.add_parser("compare", help="compare every file of two OUTDIRs")
    c.add_argument("a", type=Path, metavar="DIR_A")
    c.add_argument("b", type=Path, metavar="DIR_B")
    args = ap.parse_args(argv)
    if args.cmd == "run":
        if args.replace:
            shutil.rmtree(args.out, ignore_errors=True)
        return 1 if run(args.tree, args.out, args.only) else 0
    return 1 if compare(args.a, args.b) else 0


if __name__ == "__main__":
    sys.exit(main())
