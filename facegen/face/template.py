"""The committed neutral face: its files (package data in facegen/face/templates/), written and read.

The folder holds face.ply (binary PLY), the community's lve.txt (lips) and fdd.txt (upper face), and
regions/<name>.txt for every other region; see facegen/face/templates/README.md. Regenerate it after
changing the procedural face with `python -m facegen.face.template` (tests/test_synth_face.py checks that
the committed files equal what the code makes).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from facegen.atomic import atomic_path
from facegen.face.mesh import Mesh, read_mesh, read_region, write_mesh, write_region
from facegen.face.procedural import make_face
from facegen.face.regions import COMMUNITY_FILES

TEMPLATES = Path(__file__).resolve().with_name("templates")  # shipped inside the package (package data)


def write_templates(folder: str | os.PathLike) -> list[Path]:
    """Write the neutral face: face.ply, lve.txt (lips), fdd.txt (upper face) and regions/<name>.txt
    for every other region (the rig's layout). Returns the paths written."""
    folder = Path(folder)
    (folder / "regions").mkdir(parents=True, exist_ok=True)
    mesh = make_face()
    written = [folder / "face.ply"]
    with atomic_path(written[0]) as tmp:
        write_mesh(mesh, tmp)  # binary PLY: float32 vertices, int32 triangles
    targets = [(folder / f"{stem}.txt", mesh.regions[r]) for stem, r in COMMUNITY_FILES.items()]
    targets += [(folder / "regions" / f"{name}.txt", idx) for name, idx in sorted(mesh.regions.items())
                if name not in COMMUNITY_FILES.values()]
    for path, idx in targets:
        with atomic_path(path) as tmp:
            write_region(idx, tmp)
        written.append(path)
    return written


def load_template(folder: str | os.PathLike = TEMPLATES) -> Mesh:
    """Read a face written by write_templates (mesh and all its regions); by default the committed one."""
    folder = Path(folder)
    mesh = read_mesh(folder / "face.ply")
    for stem, region in COMMUNITY_FILES.items():
        mesh.regions[region] = read_region(folder / f"{stem}.txt")
    for path in sorted((folder / "regions").glob("*.txt")):
        mesh.regions[path.stem] = read_region(path)
    return mesh


def main(argv: list[str] | None = None) -> None:
    """Command line: write the neutral face into a folder (default: the package's templates/)."""
    parser = argparse.ArgumentParser(prog="python -m facegen.face.template",
                                     description="Write the procedural neutral face and its region files.")
    parser.add_argument("folder", nargs="?", default=str(TEMPLATES))
    for path in write_templates(parser.parse_args(argv).folder):
        print(path)


if __name__ == "__main__":
    main()
