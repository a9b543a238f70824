"""Draw the pictures of docs/arkit.md: each of the 52 ARKit shapes at weight 1 on facegen's face, front view.

    PYTHONPATH=. python docs/arkit_pictures.py [--size 320] [--out docs/img/arkit]

Writes four sheets (shapes 1-13, 14-26, 27-39, 40-52 in ARKit's order, each after the neutral face) rendered
with facegen's own rasteriser (facegen.render.raster), the shape's name under each view. For the pictures
only, the eyeballs get an iris and a pupil so that eyeLook* shows.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from facegen.arkit.shapes import arkit_shapes
from facegen.atomic import atomic_path
from facegen.render.raster import BACKGROUND, Renderer, face_colors
from facegen.face.template import load_template
from facegen.face.rig import Rig

PER_SHEET, COLUMNS = 13, 7
IRIS, PUPIL = (0.30, 0.42, 0.52), (0.05, 0.05, 0.06)  # sRGB
IRIS_DEG, PUPIL_DEG = 24.0, 10.0


def _colors(mesh) -> np.ndarray:
    colors = face_colors(mesh.regions, mesh.num_vertices)
    rig = Rig(mesh)
    for side, centre, axes in zip(("left", "right"), rig.eye_centres, rig.eye_axes, strict=True):
        idx = mesh.regions[f"{side}_eyeball"]
        u = (mesh.vertices[idx] - centre) / axes
        polar = np.degrees(np.arccos(np.clip(u[:, 2] / np.linalg.norm(u, axis=1), -1, 1)))
        colors[idx[polar < IRIS_DEG]] = IRIS
        colors[idx[polar < PUPIL_DEG]] = PUPIL
    return colors


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=320, help="pixels per view")
    parser.add_argument("--out", default=str(Path(__file__).parent / "img" / "arkit"), help="output folder")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    mesh = load_template()
    shapes = arkit_shapes(mesh)
    renderer = Renderer(mesh.faces, mesh.vertices, args.size, ("front",))
    colors = _colors(mesh)
    size, label = args.size, max(12, args.size // 20)
    font = ImageFont.load_default(size=label)
    background = tuple(round(255 * c) for c in BACKGROUND)
    # the views cropped to the columns the face covers (the widest name fits)
    neutral = renderer.render(mesh.vertices, colors)
    cols = np.nonzero((neutral != np.asarray(background, np.uint8)).any(-1).any(0))[0]
    half = max(cols[-1] - cols[0], max(font.getlength(n) for n in shapes.names)) / 2 + label
    left, width = max(0, round((cols[0] + cols[-1]) / 2 - half)), min(size, round(2 * half))
    for sheet in range(len(shapes.names) // PER_SHEET):
        names = ["neutral", *shapes.names[sheet * PER_SHEET:(sheet + 1) * PER_SHEET]]
        rows = -(-len(names) // COLUMNS)
        image = Image.new("RGB", (COLUMNS * width, rows * (size + label + 8)), background)
        draw = ImageDraw.Draw(image)
        for k, name in enumerate(names):
            vertices = mesh.vertices if name == "neutral" else mesh.vertices + shapes.offset(name)
            x, y = (k % COLUMNS) * width, (k // COLUMNS) * (size + label + 8)
            view = renderer.render(vertices, colors)[:, left:left + width]
            image.paste(Image.fromarray(np.ascontiguousarray(view)), (x, y))
            draw.text((x + width // 2, y + size + 2), name, font=font, fill=(225, 226, 230), anchor="mt")
        path = out / f"arkit_{sheet + 1}.png"
        with atomic_path(path) as tmp:
            image.save(tmp, format="png", optimize=True)
        print(path)


if __name__ == "__main__":
    main()
