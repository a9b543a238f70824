"""glTF: the parts beside the face (facegen.face.parts) as child nodes of the "Face" node.

Each part is a node (LeftEye, RightEye, UpperTeeth, LowerTeeth, Tongue) under "Face" (so it shares its
scale and the head's motion), at its pivot, with a mesh of its own: one primitive per material of
face/materials.py (the eyes: Pupil, Iris, EyeWhite), POSITION, NORMAL and indices. The animation "speech"
gains `rotation` channels (the eyes with the gaze; the lower teeth and the tongue with the jaw),
`translation` channels (the jaw's hinge) and the tongue's `weights` (its morph targets "tipUp",
"tipForward"). The face keeps its one primitive (Blender would duplicate the vertices of a split one).
"""

from __future__ import annotations

import numpy as np

from facegen.animation import Animation
from facegen.face.materials import MATERIALS
from facegen.face.mesh import vertex_normals
from facegen.face.parts import quaternions

ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


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
