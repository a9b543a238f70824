"""glTF: the face's colours per region and the parts beside the face (facegen.face.parts).

The face (its one primitive, so every reader, Blender included, gets its 23,370 vertices in their order)
wears its regions' colours as COLOR_0: per vertex, the linear RGB of face/materials.py's `face_colors` (lips,
the lips' edge blended into the skin over a few millimetres, eye whites, the mouth's inside; the same
colours as USD's GeomSubsets and the preview), under the material "Face" whose base colour is white (glTF
multiplies the two: Blender and three.js show the colours; docs/dcc.md). A face that names none of
those regions keeps the plain "Skin" material (exchange/surface.py) and no COLOR_0.

Each part is a node (LeftEye, RightEye, UpperTeeth, LowerTeeth, Tongue, EyeSockets) under "Face" (so it
shares its scale and the head's motion), at its pivot, with a mesh of its own: one primitive per material
of face/materials.py (the eyes: Pupil, Iris, EyeWhite), POSITION, NORMAL and indices. The animation
"speech" gains `rotation` channels (the eyes with the gaze; the lower teeth and the tongue with the jaw),
`translation` channels (the jaw's hinge) and the tongue's `weights` (its morph targets "tipUp",
"tipForward").
"""

from __future__ import annotations

import numpy as np

from facegen.animation import Animation
from facegen.exchange.surface import MATERIAL_NAME, SKIN_COLOR, SKIN_METALLIC, SKIN_ROUGHNESS
from facegen.face.materials import MATERIALS, SKIN, face_colors, srgb_to_linear
from facegen.face.mesh import vertex_normals
from facegen.face.parts import quaternions

ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


FACE_MATERIAL = "Face"


def face_surface(anim: Animation, accessor) -> tuple[object, int | None]:
    """The face's pygltflib Material and its COLOR_0 accessor (None when the face names no coloured
    region: the plain skin)."""
    import pygltflib as g

    colors = face_colors(anim.faces, anim.regions, anim.num_vertices)
    if colors is None:
        return g.Material(name=MATERIAL_NAME, pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[*SKIN_COLOR, 1.0], metallicFactor=SKIN_METALLIC,
            roughnessFactor=SKIN_ROUGHNESS)), None
    skin = MATERIALS[SKIN]
    material = g.Material(name=FACE_MATERIAL, pbrMetallicRoughness=g.PbrMetallicRoughness(
        baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=skin.metallic, roughnessFactor=skin.roughness))
    return material, accessor(srgb_to_linear(colors), "VEC3", ARRAY_BUFFER)


def add_parts(anim: Animation, accessor, nodes: list, meshes: list, materials: list, samplers: list,
              channels: list, time_input: int, face_node: int = 0) -> None:
    """Append the parts' nodes, meshes, materials and animation channels to a document being built
    (exchange/gltf.py's `build`: `accessor(data, kind, target, with_bounds)` adds an accessor)."""
    import pygltflib as g

    tracks = anim.part_meshes()
    if not tracks:
        return
    index_of = {m.name: i for i, m in enumerate(materials)}

    def material(name: str) -> int:
        if name not in index_of:
            m = MATERIALS[name]
            materials.append(g.Material(name=name, pbrMetallicRoughness=g.PbrMetallicRoughness(
                baseColorFactor=[*m.color, 1.0], metallicFactor=m.metallic, roughnessFactor=m.roughness)))
            index_of[name] = len(materials) - 1
        return index_of[name]

    def channel(node: int, path: str, values: np.ndarray, kind: str) -> None:
        samplers.append(g.AnimationSampler(input=time_input, output=accessor(
            np.ascontiguousarray(values, np.float32), kind, None), interpolation="LINEAR"))
        channels.append(g.AnimationChannel(sampler=len(samplers) - 1,
                                           target=g.AnimationChannelTarget(node=node, path=path)))

    children = []
    for track in tracks:
        part = track.part
        primitives = []
        for name, a, b in part.groups:
            faces = part.faces[a:b]
            first, last = int(faces.min()), int(faces.max()) + 1
            local = np.ascontiguousarray(part.vertices[first:last], np.float32)
            tris = (faces - first).astype(np.uint16)
            targets = [{"POSITION": accessor(np.ascontiguousarray(o[first:last], np.float32), "VEC3",
                                             ARRAY_BUFFER, True)} for o in part.targets.values()]
            primitives.append(g.Primitive(
                attributes=g.Attributes(POSITION=accessor(local, "VEC3", ARRAY_BUFFER, True),
                                        NORMAL=accessor(vertex_normals(local, tris), "VEC3", ARRAY_BUFFER)),
                indices=accessor(tris.reshape(-1), "SCALAR", ELEMENT_ARRAY_BUFFER, True), mode=g.TRIANGLES,
                material=material(name), targets=targets or None))
        extras = {"targetNames": list(part.targets)} if part.targets else None
        meshes.append(g.Mesh(name=part.name, primitives=primitives, extras=extras,
                             weights=[0.0] * len(part.targets) if part.targets else None))
        quats = quaternions(track.rotation).astype(np.float32)
        nodes.append(g.Node(name=part.name, mesh=len(meshes) - 1, translation=track.translation[0].tolist(),
                            rotation=quats[0].astype(float).tolist()))
        node = len(nodes) - 1
        children.append(node)
        if np.ptp(quats, 0).max() > 0:
            channel(node, "rotation", quats, "VEC4")
        if np.ptp(track.translation, 0).max() > 0:
            channel(node, "translation", track.translation, "VEC3")
        if track.weights is not None and part.targets:
            channel(node, "weights", np.clip(track.weights, 0, 1).reshape(-1), "SCALAR")
    nodes[face_node].children = (nodes[face_node].children or []) + children
