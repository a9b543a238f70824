"""The face's regions coloured in glTF as in USD and the preview (exchange/gltf_parts.py): COLOR_0 on the
face's one primitive holds face/materials.py's colours per vertex (lips, eye whites, the mouth's inside, the
lips' edge blended), under the white "Face" material; the 23,370 vertices keep their order and positions in
facegen's reader and in Blender; Blender and three.js show the colours, and `facegen render` of the file
paints the lips."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from helpers import rig_clip

from facegen.exchange import gltf, read_animation, write_animation
from facegen.face.materials import MATERIALS, lip_blend

REPO = Path(__file__).resolve().parents[1]
BLENDER_PYTHON = REPO / ".venv-blender" / "bin" / "python"


@pytest.fixture(scope="module")
def clip():
    return rig_clip(20, seed=5)


@pytest.fixture(scope="module")
def glb(clip, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("colors") / "face.glb"
    write_animation(clip, out)
    return out


def region_vertices(clip) -> dict[str, np.ndarray]:
    """Vertices that wear one material fully: the lips' core (blend 1), skin away from every region (blend
    0), the eyeball caps and the mouth's inside away from the lips' edge."""
    blend = lip_blend(clip.faces, np.asarray(clip.regions["lips"]), clip.num_vertices)
    named = np.zeros(clip.num_vertices, bool)
    for r in ("lips", "left_eyeball", "right_eyeball", "mouth_cavity"):
        named[np.asarray(clip.regions[r])] = True
    eyes = np.concatenate([clip.regions["left_eyeball"], clip.regions["right_eyeball"]])
    cavity = np.asarray(clip.regions["mouth_cavity"])
    return {"Lips": np.flatnonzero(blend == 1), "Skin": np.flatnonzero(~named & (blend == 0)),
            "EyeWhite": eyes, "MouthInterior": cavity[blend[cavity] == 0]}


def test_color_0_per_region(clip, glb):
    doc = pygltflib.GLTF2().load(str(glb))
    face = doc.meshes[0]
    assert face.name == "Face" and len(face.primitives) == 1
    prim = face.primitives[0]
    material = doc.materials[prim.material]
    assert material.name == "Face" and material.pbrMetallicRoughness.baseColorFactor == [1.0, 1.0, 1.0, 1.0]
    assert doc.accessors[prim.attributes.COLOR_0].type == "VEC3"
    colors = gltf.GltfFile(glb).accessor(prim.attributes.COLOR_0)
    assert colors.shape == (23370, 3)
    groups = region_vertices(clip)
    assert all(len(v) > 50 for v in groups.values()), {k: len(v) for k, v in groups.items()}
    for name, idx in groups.items():  # linear RGB of the one materials table, as USD's diffuseColor
        assert np.allclose(colors[idx], MATERIALS[name].color, atol=1e-5), name
    lips, skin = np.asarray(MATERIALS["Lips"].color), np.asarray(MATERIALS["Skin"].color)
    edge = np.flatnonzero(np.all(np.abs(colors - lips) > 0.01, 1) & np.all(np.abs(colors - skin) > 0.01, 1)
                          & (lip_blend(clip.faces, np.asarray(clip.regions["lips"]), clip.num_vertices) > 0))
    assert len(edge) > 100  # the lips' edge blended over rings of vertices, not a jagged step
    back = read_animation(glb)  # facegen's reader: the same vertices in the same order
    assert back.num_vertices == 23370 and np.array_equal(back.template, clip.template)
    assert np.array_equal(back.faces, clip.faces)


def test_face_without_regions_keeps_the_skin(clip, tmp_path):
    out = tmp_path / "plain.glb"
    write_animation(replace(clip, regions={}), out, write_audio=False)
    doc = pygltflib.GLTF2().load(str(out))
    prim = doc.meshes[0].primitives[0]
    material = doc.materials[prim.material]
    assert prim.attributes.COLOR_0 is None and material.name == "Skin"
    assert material.pbrMetallicRoughness.baseColorFactor == pytest.approx([*MATERIALS["Skin"].color, 1.0])


def test_validator_passes(glb):
    out = subprocess.run([sys.executable, "-m", "facegen", "validate", str(glb)],
                         capture_output=True, text=True, check=False, cwd=REPO)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "gltf-validator  glTF-Validator" in out.stdout and " 0 errors, 0 warnings" in out.stdout


def test_render_of_the_glb_paints_the_lips(clip, glb, tmp_path):
    """`facegen render face.glb` (its reading path) draws the lips in their colour: pixels whose green is
    under 0.68 of their red (lips: 0.61 unlit; skin 0.79) are many, as in the picture of the clip itself,
    and none without the regions."""
    from PIL import Image

    from facegen.render import _read_input, _with_parts, render_still

    def lip_pixels(anim, name: str) -> int:
        image = np.asarray(Image.open(render_still(anim, tmp_path / name, frame=10, size=256)), np.float64)
        lit = image[..., 0] > 60
        return int((lit & (image[..., 1] < 0.68 * image[..., 0])).sum())

    drawn = _with_parts(_read_input(glb))
    assert drawn.num_vertices == 23370 and "lips" in drawn.regions
    source, from_file = lip_pixels(clip, "source.png"), lip_pixels(drawn, "file.png")
    plain = lip_pixels(replace(drawn, regions={}), "plain.png")
    assert source > 500 and abs(from_file - source) <= 0.05 * source, (source, from_file)
    assert plain < 0.02 * source, plain


BLENDER_SCRIPT = """
import json, sys, bpy, numpy as np
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[1])
face = max((o for o in bpy.context.scene.objects if o.type == 'MESH'), key=lambda o: len(o.data.vertices))
me = face.data
attr = me.color_attributes[0]
colors = np.zeros(len(attr.data) * 4, np.float32)
attr.data.foreach_get('color', colors)
loops = np.zeros(len(me.loops), np.int64)
me.loops.foreach_get('vertex_index', loops)
per_vertex = np.zeros((len(me.vertices), 3), np.float32)
per_vertex[loops] = colors.reshape(-1, 4)[:, :3]
co = np.zeros(len(me.vertices) * 3, np.float32)
me.vertices.foreach_get('co', co)
np.save(sys.argv[2], np.stack([per_vertex, co.reshape(-1, 3)]))
material = face.material_slots[0].material
links = [[l.from_node.bl_idname, l.to_socket.name] for l in material.node_tree.links]
print('RESULT ' + json.dumps({'material': material.name, 'links': links, 'scale': list(face.scale)}))
"""


@pytest.mark.skipif(not BLENDER_PYTHON.exists(), reason="no .venv-blender (make blender-venv)")
def test_blender_shows_the_lips(clip, glb, tmp_path):
    """Blender's own glTF importer: one mesh of 23,370 vertices in the file's order, at the template's
    positions; its colour attribute wears the lips' colour on the lips and the skin's elsewhere, and the
    material's base colour comes from it."""
    script = tmp_path / "check.py"
    script.write_text(BLENDER_SCRIPT)
    saved = tmp_path / "seen.npy"
    run = subprocess.run([str(BLENDER_PYTHON), str(script), str(glb), str(saved)], capture_output=True,
                         text=True, timeout=300, check=False)
    line = next((x for x in run.stdout.splitlines() if x.startswith("RESULT ")), None)
    assert line, run.stdout[-2000:] + run.stderr[-2000:]
    seen = json.loads(line[7:])
    assert seen["material"] == "Face" and ["ShaderNodeVertexColor", "Base Color"] in seen["links"], seen
    colors, co = np.load(saved)
    assert len(co) == 23370
    # glTF's Y-up (x, y, z) is Blender's Z-up (x, -z, y); the node's scale (0.2) stays on the object
    assert np.allclose(co, clip.template[:, [0, 2, 1]] * [1, -1, 1], atol=1e-5)
    for name, idx in region_vertices(clip).items():  # Blender keeps 8-bit colours: within 1/255-ish
        assert np.abs(colors[idx] - MATERIALS[name].color).max() < 0.01, name
    assert np.abs(colors[region_vertices(clip)["Lips"]] - MATERIALS["Skin"].color).min(0).max() > 0.15


THREE_SCRIPT = """
import { readFileSync } from 'node:fs';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
const data = readFileSync(process.argv[2]);
const ids = JSON.parse(readFileSync(process.argv[3], 'utf8'));
new GLTFLoader().parse(data.buffer.slice(data.byteOffset, data.byteOffset + data.byteLength), '', (gltf) => {
  const size = (o) => o.geometry.attributes.position.count;
  let face = null;
  gltf.scene.traverse((o) => { if (o.isMesh && (!face || size(o) > size(face))) face = o; });
  const color = face.geometry.attributes.color;
  console.log('RESULT ' + JSON.stringify({material: face.material.name,
    vertexColors: face.material.vertexColors, count: size(face),
    colors: Object.fromEntries(Object.entries(ids).map(([k, v]) => [k, v.map((i) => color.getX(i) + ',' +
      color.getY(i) + ',' + color.getZ(i))]))}));
}, (error) => { console.error(String(error)); process.exit(1); });
"""


def test_threejs_shows_the_lips(clip, glb, tmp_path):
    """three.js's GLTFLoader (the npm package of `make node-deps`, in node): the face's material gets
    `vertexColors` (so COLOR_0 multiplies its white base colour) and each region's vertices its colour."""
    modules = REPO / "facegen" / "assets" / "node_modules"
    if not (shutil.which("node") and (modules / "three" / "package.json").is_file()):
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("node or the npm package three is missing in CI: `make node-deps` should have run")
        pytest.skip("node or the npm package three is missing: run `make node-deps`")
    (tmp_path / "node_modules").symlink_to(modules, target_is_directory=True)
    (tmp_path / "check.mjs").write_text(THREE_SCRIPT)
    groups = {k: v[:: max(1, len(v) // 20)].tolist() for k, v in region_vertices(clip).items()}
    (tmp_path / "ids.json").write_text(json.dumps(groups))
    run = subprocess.run(["node", "check.mjs", str(glb), "ids.json"], cwd=tmp_path, capture_output=True,
                         text=True, timeout=120, check=False)
    line = next((x for x in run.stdout.splitlines() if x.startswith("RESULT ")), None)
    assert run.returncode == 0 and line, run.stdout[-2000:] + run.stderr[-2000:]
    seen = json.loads(line[7:])
    assert seen["material"] == "Face" and seen["vertexColors"] is True and seen["count"] == 23370, seen
    for name, colors in seen["colors"].items():
        got = np.array([[float(x) for x in c.split(",")] for c in colors])
        assert np.allclose(got, MATERIALS[name].color, atol=1e-5), name
