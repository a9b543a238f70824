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

`compare DIR_A DIR_B` compares every file of the two folders (logs/ aside) with file_compare.py: bytes
first; else the values each kind of file holds (arrays, USD stages, glTF accessors, WAV samples, the numbers
in JSON/CSV/TextGrid/stdout). One line per file: `identical`, `same values, bytes differ (max diff X)` when
every number is within file_compare.TOLERANCE (1e-6), or `DIFFERENT: why`. Exit status 1 when a file
differs. The fields that legitimately differ from run to run are listed in file_compare.IGNORED_*, nothing
else.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from file_compare import compare

REPO = Path(__file__).resolve().parents[1]
INPUTS_COMMIT = "0dc2807"  # the inputs' bytes come from this commit (git show), whichever tree runs

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
