"""USD: the parts beside the face (facegen.face.parts) and the materials of every surface (face/materials.py).

Layout added to a written stage (exchange/usd.py) when the Animation has parts:

    /Face/Looks/<Material>   Material + UsdPreviewSurface "Surface" for each material of face/materials.py
                             (diffuseColor, roughness, metallic) that a surface wears
    /Face/Mesh               GeomSubsets (familyName materialBind, elementType face) "Lips", "EyeWhite",
                             "MouthInterior" (and "Skin", the rest), each bound to its material
    /Face/<Part>             Xform per part (LeftEye, RightEye, UpperTeeth, LowerTeeth, Tongue, EyeSockets):
                             xformOp translate (where its pivot is) and orient (a quaternion); time-sampled
                             per frame where the part moves (the eyes turn with the gaze, the lower teeth
                             and the tongue with the jaw), a constant value where it does not (the upper
                             teeth, the eye sockets' lining)
    /Face/<Part>/<Part>Mesh  Mesh in the part's own coordinates (about its pivot), its GeomSubsets per
                             material bound (the eyes: Pupil, Iris, EyeWhite); the tongue's points have one
                             time sample per frame (its tip rising and coming forward)

The face's points and topology are unchanged: BIWI-topology tools read /Face/Mesh as before.
"""

from __future__ import annotations

import numpy as np

from facegen.animation import Animation
from facegen.exchange.usd_values import vec3f_array
from facegen.face.materials import MATERIALS, face_triangle_materials
from facegen.face.parts import quaternions

LOOKS = "/Face/Looks"


def author_parts(stage, anim: Animation, mesh_path: str) -> None:
    """Materials on the face mesh at `mesh_path` and the parts' prims, if `anim` has parts."""
    from pxr import UsdGeom

    tracks = anim.part_meshes()
    if not tracks:
        return
    looks: dict = {}
    face = UsdGeom.Mesh.Get(stage, mesh_path)
    subsets = face_triangle_materials(anim.faces, anim.regions, anim.num_vertices)
    _bind_subsets(stage, face, [(name, idx) for name, idx in subsets.items()], looks)
    for track in tracks:
        _author_part(stage, track, looks)


def _material(stage, name: str, looks: dict):
    from pxr import Gf, Sdf, UsdShade

    if name not in looks:
        m = MATERIALS[name]
        material = UsdShade.Material.Define(stage, f"{LOOKS}/{name}")
        shader = UsdShade.Shader.Define(stage, f"{LOOKS}/{name}/Surface")
        shader.CreateIdAttr("UsdPreviewSurface")
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*m.color))
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(m.roughness)
        shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(m.metallic)
        material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        looks[name] = material
    return looks[name]


def _bind_subsets(stage, mesh, groups: list[tuple[str, np.ndarray]], looks: dict) -> None:
    """A GeomSubset per (material, triangle indices) on `mesh`, each bound to its material."""
    from pxr import UsdGeom, UsdShade, Vt

    for name, idx in groups:
        subset = UsdGeom.Subset.Define(stage, mesh.GetPath().AppendChild(name))
        subset.CreateElementTypeAttr(UsdGeom.Tokens.face)
        subset.CreateFamilyNameAttr(UsdShade.Tokens.materialBind)
        subset.CreateIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(idx, np.int32)))
        UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(_material(stage, name, looks))
    UsdGeom.Subset.SetFamilyType(mesh, UsdShade.Tokens.materialBind, UsdGeom.Tokens.partition)


def _author_part(stage, track, looks: dict) -> None:
    from pxr import Gf, UsdGeom, UsdShade, Vt

    part = track.part
    xform = UsdGeom.Xform.Define(stage, f"/Face/{part.name}")
    move = xform.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
    turn = xform.AddOrientOp(UsdGeom.XformOp.PrecisionFloat)
    quats = quaternions(track.rotation)  # x, y, z, w
    moving = bool(np.ptp(track.translation, 0).max() > 0 or np.ptp(quats, 0).max() > 0)
    if moving:
        for t in range(len(quats)):
            move.Set(Gf.Vec3d(*track.translation[t].tolist()), float(t))
            x, y, z, w = quats[t].tolist()
            turn.Set(Gf.Quatf(w, x, y, z), float(t))
    else:
        move.Set(Gf.Vec3d(*track.translation[0].tolist()))
        x, y, z, w = quats[0].tolist()
        turn.Set(Gf.Quatf(w, x, y, z))
    mesh = UsdGeom.Mesh.Define(stage, f"/Face/{part.name}/{part.name}Mesh")  # Blender names it so
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(part.faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(part.faces.reshape(-1).astype(np.int32)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    rest = np.ascontiguousarray(part.vertices, np.float32)
    points = mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(rest))
    mesh.CreateExtentAttr(UsdGeom.PointBased.ComputeExtent(Vt.Vec3fArray.FromNumpy(rest)))
    if track.weights is not None and np.any(track.weights):
        offsets = np.stack(list(part.targets.values())).astype(np.float64)
        for t, w in enumerate(track.weights):
            posed = rest + np.tensordot(w, offsets, 1).astype(np.float32)
            points.Set(vec3f_array(posed), float(t))
    groups = [(name, np.arange(a, b)) for name, a, b in part.groups]
    if len(groups) == 1:
        UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(_material(stage, groups[0][0], looks))
    else:
        _bind_subsets(stage, mesh, groups, looks)
