"""USD: the animation as one UsdGeom.Mesh with one `points` time sample per frame (or UsdSkel blend
shapes), audio beside it.

Layout of a written file (`out.usda`, `.usdc` or `.usd`; `.usd` is binary crate):

    /Face          Xform, kind=component, the stage's defaultPrim; with head motion (facegen.head) its
                   xformOpOrder is translate:pivot, rotateZXY:head (pitch, yaw, roll degrees, one time sample
                   per frame), !invert!translate:pivot: the head turns about the top of the neck
    /Face/Mesh     Mesh: faceVertexCounts (all 3), faceVertexIndices, subdivisionScheme "none",
                   orientation rightHanded (BIWI triangles wind counter-clockwise seen from the front, so
                   normals face +Z, out of the face); `points` and `extent` have one time sample per
                   frame at time codes 0..T-1, and their default (non-animated) values hold the rest pose;
                   primvars:st (vertex texCoord2f, exchange/surface.py's UVs), primvars:displayColor
                   (constant skin colour), MaterialBindingAPI -> /Face/Looks/Skin
    /Face/Looks/Skin  Material; its Shader "Surface" a UsdPreviewSurface (diffuseColor the skin colour,
                   metallic 0, roughness 0.6) connected to outputs:surface
    /Face/<Part>   with parts (an Animation from the network): eyes, teeth, tongue, and the face's
                   material subsets (usd_parts.py)
    /Face/Audio    SpatialAudio: filePath @./out.wav@ (relative to the layer), auralMode nonSpatial,
                   playbackMode onceFromStart (play once from startTime to the audio's end); startTime
                   is its schema fallback 0 (authoring a timecode forces usdc crate 0.9 and a warning)

A points clip longer than usd_clips.CLIP_THRESHOLD frames (`clips="auto"`) keeps this layout, but its
`points` and `extent` samples (and their rest-pose defaults) live in USD value clips in `out.clips/` beside
the file, stitched by a clip set on /Face/Mesh, so that the frames are never all in memory (usd_clips.py).

With `mode="blendshapes"` the frames are UsdSkel blend shapes instead of `points` samples: /Face is a
SkelRoot, and a Skeleton, a SkelAnimation with one blendShapeWeights sample per frame and one BlendShape
per target of the rig's basis (exchange/morph_targets.py: PCA, or with `rig="arkit"` the 52 ARKit shapes) are
added (layout in usd_skel.py); customLayerData["facegen"]["reconstruction"] states the error of the
reconstruction.

Stage metadata: timeCodesPerSecond = framesPerSecond = fps, startTimeCode 0, endTimeCode T-1, upAxis Y,
metersPerUnit (`meters_per_unit`, default 0.2: BIWI coordinates are scaled to unit surface area, and a
face mask is about 0.04 m², so one unit is about 0.2 m and the face is about 19 cm tall), and
customLayerData["facegen"] = {version, mode, fps, frames, metadata (the animation's metadata, JSON-able values
only; lists of one scalar type become typed arrays, other lists JSON strings)}.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from facegen import __version__
from facegen.animation import DEFAULT_FPS, Animation, check_animation
from facegen.atomic import Transaction
from facegen.audio import load_audio
from facegen.errors import FacegenError
from facegen.exchange import usd_clips, usd_skel
from facegen.exchange.formats import by_module
from facegen.exchange.head_read import usd_head
from facegen.exchange.morph_targets import targets_as_written, writer_basis
from facegen.exchange.surface import MATERIAL_NAME, SKIN_COLOR, SKIN_METALLIC, SKIN_ROUGHNESS, face_uvs
from facegen.exchange.usd_parts import author_parts
from facegen.exchange.usd_values import python_value, usd_dict, vec3f_array
from facegen.exchange.wav import atomic_with_sidecar
from facegen.face.mesh import Mesh, check_topology

FORMAT = by_module(__name__)
MODES = ("points", "blendshapes")
DEFAULT_METERS_PER_UNIT = 0.2
ROOT_PATH = "/Face"
MESH_PATH = "/Face/Mesh"
AUDIO_PATH = "/Face/Audio"
MATERIAL_PATH = f"/Face/Looks/{MATERIAL_NAME}"


def write(
    anim: Animation,
    path: str | os.PathLike,
    *,
    mode: str | None = None,
    rig: str = "pca",
    morph_targets: int | str | None = None,
    tolerance: float | None = None,
    clips: str | int = "auto",
    meters_per_unit: float = DEFAULT_METERS_PER_UNIT,
    write_audio: bool = True,
    audio_source: str | os.PathLike | None = None,
) -> list[Path]:
    """Write `anim` as a USD file (format from the extension) and its audio as a WAV beside it.

    `mode` is "points" (one `points` sample per frame) or "blendshapes" (UsdSkel blend shapes); None is
    "blendshapes" with `rig="arkit"`, else "points". `rig` chooses the blend shapes (morph_targets.py):
    "pca", whose `morph_targets` fixes their number K, an int, or "all" for one per frame (by default K is
    the fewest keeping every vertex within `tolerance` x the face's size, default pca.DEFAULT_TOLERANCE),
    or "arkit", the 52 ARKit shapes named by ARKit's names (the face needs the rig's regions).
    `clips` (points mode): "auto" writes a clip longer than usd_clips.CLIP_THRESHOLD frames as USD value
    clips, one layer per usd_clips.CLIP_FRAMES frames in the folder `out.clips/` beside `out.usdc`, so that
    memory stays bounded (usd_clips.py); "never" always writes one file; a number N writes value clips of N
    frames whatever the length.
    Returns the asset's files: the USD file, then the WAV when the animation has audio and `write_audio` is
    true, then the clip folder's files (rest layer, manifest, clip layers) when there are clips.
    `audio_source` is the input audio file: when it is the sidecar itself (`clip.wav` animated to `clip.usda`)
    it is referenced, not overwritten.
    """
    from pxr import Sdf, Usd

    check_animation(anim)
    path = Path(path)
    if path.suffix.lower() not in FORMAT.extensions:
        raise FacegenError(f"{path} is not a USD file name: use one of {', '.join(FORMAT.extensions)}")
    if not meters_per_unit > 0:
        raise FacegenError(f"meters per unit must be positive, got {meters_per_unit}")
    basis = _check_mode(anim, mode, rig, morph_targets, tolerance)
    per_clip = usd_clips.clip_frames(clips, anim.num_frames, basis is None)
    audio = anim.audio if write_audio and anim.audio is not None and len(anim.audio) else None
    clip_files: list[Path] = []
    folder = usd_clips.folder_of(path)
    with (Transaction() as transaction,
          atomic_with_sidecar(path, audio, anim.sample_rate, audio_source) as (tmp, wav)):
        work = transaction.folder(folder) if per_clip else None
        if not per_clip:
            usd_clips.remove_stale(path, transaction)
        layer = Sdf.Layer.CreateNew(str(tmp))
        if layer is None:
            raise FacegenError(f"cannot create USD layer {tmp}: check the output folder")
        stage = Usd.Stage.Open(layer)
        audio_asset = f"./{wav.name}" if wav is not None else None
        if basis is None:
            _author_stage(stage, anim, meters_per_unit, audio_asset)
            del stage
            if per_clip:
                usd_clips.author_clip_set(layer, MESH_PATH, path, anim.num_frames, per_clip)
                written = usd_clips.write_clip_layers(anim, work, path.stem, MESH_PATH, per_clip)
                clip_files = [folder / f.name for f in written]
            else:
                _author_samples(layer, anim)
        else:
            names, offsets, weights = targets_as_written(basis)
            info = {"reconstruction": usd_skel.layer_info(basis, len(names))}
            extents = usd_skel.frame_extents(anim.template, offsets, weights)
            bounds = np.stack([extents[:, 0].min(0), extents[:, 1].max(0)])
            _author_stage(stage, anim, meters_per_unit, audio_asset, "blendshapes", info, bounds)
            usd_skel.author_skeleton(stage, MESH_PATH, names, offsets)
            del stage
            usd_skel.author_samples(layer, weights, extents, MESH_PATH, ROOT_PATH)
        if not layer.Save():
            raise FacegenError(f"cannot write {path}: check free disk space and permissions")
        del layer
    return [path, *([] if wav is None else [wav]), *clip_files]


def _check_mode(anim: Animation, mode: str | None, rig: str, morph_targets: int | str | None,
                tolerance: float | None):
    """Refuse an unknown mode or blendshape options in points mode; the rig's basis for blendshapes."""
    if mode is None:
        mode = "blendshapes" if rig == "arkit" else "points"
    if mode not in MODES:
        raise FacegenError(f"unknown USD mode {mode!r}: use one of {', '.join(MODES)}")
    if mode == "points" and rig == "arkit":
        raise FacegenError("the arkit rig writes UsdSkel blend shapes: drop the points mode",
                           param=("rig", "mode"))
    if mode == "points":
        given = [n for n, v in (("morph targets", morph_targets), ("tolerance", tolerance)) if v is not None]
        if given:
            raise FacegenError(
                f"{' and '.join(given)} apply to USD blendshapes only: "
                "use the blendshapes mode or drop them",
                param=("mode", *(p for p, v in (("morph_targets", morph_targets), ("tolerance", tolerance))
                                 if v is not None))
            )
        return None
    return writer_basis(anim, rig, morph_targets, tolerance)


def _author_stage(
    stage, anim: Animation, meters_per_unit: float, audio_asset: str | None, mode: str = "points",
    info: dict | None = None, bounds: np.ndarray | None = None,
) -> None:
    """Everything except the per-frame samples: stage metadata, prims, topology, rest pose, look, audio;
    `info` is added to customLayerData["facegen"]; `bounds` (blendshapes: every frame's) is the default
    extent of the mesh and the SkelRoot (else the rest pose's, on the mesh)."""
    from pxr import Kind, Sdf, Usd, UsdGeom, UsdMedia, UsdSkel, Vt

    frames = anim.num_frames
    stage.SetTimeCodesPerSecond(float(anim.fps))
    stage.SetFramesPerSecond(float(anim.fps))
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(float(frames - 1))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))

    root = (UsdSkel.Root if mode == "blendshapes" else UsdGeom.Xform).Define(stage, ROOT_PATH)
    Usd.ModelAPI(root.GetPrim()).SetKind(Kind.Tokens.component)
    stage.SetDefaultPrim(root.GetPrim())
    if anim.head is not None:
        _author_head(root, anim.head, anim.head_pivot)

    mesh = UsdGeom.Mesh.Define(stage, MESH_PATH)
    faces = np.ascontiguousarray(anim.faces, dtype=np.int32)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.reshape(-1)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    rest = np.ascontiguousarray(anim.template, dtype=np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(rest))
    box = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(
        np.stack([rest.min(0), rest.max(0)]) if bounds is None else bounds, dtype=np.float32))
    mesh.CreateExtentAttr(box)
    if mode == "blendshapes":
        root.CreateExtentAttr(box)
    _author_look(stage, mesh, rest)
    author_parts(stage, anim, MESH_PATH)  # materials per region, eyes, teeth, tongue (usd_parts.py)

    if audio_asset is not None:
        sound = UsdMedia.SpatialAudio.Define(stage, AUDIO_PATH)
        sound.CreateFilePathAttr(Sdf.AssetPath(audio_asset))
        sound.CreateAuralModeAttr(UsdMedia.Tokens.nonSpatial)
        sound.CreatePlaybackModeAttr(UsdMedia.Tokens.onceFromStart)
        # startTime/endTime keep their schema fallbacks: startTime 0 is where the audio starts, and
        # onceFromStart ignores endTime. Authoring a timecode value would force usdc crate 0.9.0 and a
        # pxr warning on every write.

    stage.GetRootLayer().customLayerData = {
        "facegen": {
            "version": __version__,
            "mode": mode,
            "fps": float(anim.fps),
            "frames": int(frames),
            "metadata": usd_dict(anim.metadata),
            **(info or {}),
        }
    }


def _author_head(root, angles: np.ndarray, pivot: np.ndarray) -> None:
    """The head's motion on /Face (facegen.head): translate to the pivot, rotateZXY (pitch, yaw, roll) in
    degrees with one time sample per frame, translate back; the points stay face-local."""
    from pxr import Gf, UsdGeom

    xform = UsdGeom.Xformable(root.GetPrim())
    move = xform.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble, "pivot")
    move.Set(Gf.Vec3d(*np.asarray(pivot, np.float64).tolist()))
    turn = xform.AddRotateZXYOp(UsdGeom.XformOp.PrecisionFloat, "head")
    for t, (yaw, pitch, roll) in enumerate(np.asarray(angles, np.float64).tolist()):
        turn.Set(Gf.Vec3f(pitch, yaw, roll), float(t))
    xform.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble, "pivot", isInverseOp=True)


def _author_look(stage, mesh, template: np.ndarray) -> None:
    """UVs (primvars:st), displayColor and the skin UsdPreviewSurface material bound to the mesh."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt

    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                 UsdGeom.Tokens.vertex)
    st.Set(Vt.Vec2fArray.FromNumpy(face_uvs(template)))
    mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(*SKIN_COLOR)]))
    UsdGeom.Scope.Define(stage, MATERIAL_PATH.rsplit("/", 1)[0])
    material = UsdShade.Material.Define(stage, MATERIAL_PATH)
    shader = UsdShade.Shader.Define(stage, f"{MATERIAL_PATH}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*SKIN_COLOR))
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(SKIN_METALLIC)
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(SKIN_ROUGHNESS)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)


def _author_samples(layer, anim: Animation) -> None:
    """One `points` and one `extent` time sample per frame, written straight into the layer.

    Called with no stage open on the layer: a stage listening to the layer slows this loop by half.
    """
    from pxr import Sdf, UsdGeom

    points = Sdf.Path(MESH_PATH).AppendProperty("points")
    extent = Sdf.Path(MESH_PATH).AppendProperty("extent")
    with Sdf.ChangeBlock():
        # a FrameStream: the next block computed while this one is copied; no more than two besides the layer
        for start, block in anim.frame_blocks(256, ahead=True):
            for i in range(len(block)):
                frame = vec3f_array(block[i])
                layer.SetTimeSample(points, float(start + i), frame)
                layer.SetTimeSample(extent, float(start + i), UsdGeom.PointBased.ComputeExtent(frame))


# ---- reading -----------------------------------------------------------------------------------------


def open_stage(path: str | os.PathLike):
    """Open a USD stage; a missing or unreadable file is a FacegenError."""
    from pxr import Sdf, Tf, Usd

    path = Path(path)
    if not path.is_file():
        raise FacegenError(f"USD file {path} does not exist: pass an existing .usda/.usdc/.usd/.usdz file")
    # usd-core maps crate files into memory: every frame read stays resident (as file pages, counted in the
    # process's RSS) while the stage is open, 4.2 GB for a 10-minute clip. Reading with pread instead keeps
    # only the frame being read. pxr reads the setting once, at the first crate file it opens; a value the
    # user set wins.
    os.environ.setdefault("USDC_USE_PREAD", "1")
    try:
        cached = Sdf.Layer.Find(str(path))
        if cached is not None:  # a layer still held in this process: read the file as it is now
            cached.Reload(force=True)
        stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:
        raise FacegenError(
            f"cannot open USD file {path} ({_tf_message(exc)}): pass a valid USD file"
        ) from exc
    if stage is None:
        raise FacegenError(f"cannot open USD file {path}: pass a valid USD file")
    return stage


def _tf_message(exc: Exception) -> str:
    """The first message of a pxr error, on one line (pxr's text holds C++ function names and files)."""
    try:
        text = str(exc)
    except UnicodeError:  # pxr quotes the file's bytes, which need not be UTF-8
        text = "the file's text is not valid UTF-8"
    found = re.findall(r" : '([^']*)'", text)
    return found[0] if found else " ".join(text.split())[:200]


def find_mesh(stage):
    """The animated face mesh: the first Mesh under the default prim (else anywhere), or None."""
    from pxr import Usd, UsdGeom

    root = stage.GetDefaultPrim()
    prims = Usd.PrimRange(root) if root else stage.Traverse()
    for prim in prims:
        if prim.IsA(UsdGeom.Mesh):
            return UsdGeom.Mesh(prim)
    if root:
        for prim in stage.Traverse():
            if prim.IsA(UsdGeom.Mesh):
                return UsdGeom.Mesh(prim)
    return None


def find_audio(stage):
    """The first SpatialAudio prim of the stage, or None."""
    from pxr import UsdMedia

    for prim in stage.Traverse():
        if prim.IsA(UsdMedia.SpatialAudio):
            return UsdMedia.SpatialAudio(prim)
    return None


def mesh_faces(mesh) -> np.ndarray:
    """The mesh's triangles as [F, 3] int32; a mesh with other polygons is a FacegenError."""
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int32)
    if len(counts) == 0 or not (counts == 3).all() or len(indices) != 3 * len(counts):
        raise FacegenError(
            f"mesh {mesh.GetPath()} is not a triangle mesh (face sizes {sorted(set(counts.tolist()))[:5]}): "
            "triangulate it before export"
        )
    return indices.reshape(-1, 3)


class PointsFrames:
    """A mesh's `points` at its time samples as a read-only sequence of [V, 3] float32 arrays, each read from
    the stage when asked: a long clip (value clips or one file) is never held whole."""

    def __init__(self, attr, times: list[float]) -> None:
        self.attr, self.times = attr, times

    def __len__(self) -> int:
        return len(self.times)

    def value(self, i: int):
        """Frame i as the stage gives it (a Vt.Vec3fArray), None where a value clip is missing."""
        return self.attr.Get(self.times[i])

    def __getitem__(self, i: int) -> np.ndarray:
        value = self.value(i)
        return np.asarray(value if value is not None else np.zeros((0, 3)), dtype=np.float32)

    def __iter__(self) -> Iterator[np.ndarray]:
        return (self[i] for i in range(len(self)))


def points_samples(mesh) -> tuple[list[float], PointsFrames]:
    """The time codes of the mesh's `points` samples and the [V, 3] float32 arrays at them (read lazily)."""
    attr = mesh.GetPointsAttr()
    times = list(attr.GetTimeSamples())
    return times, PointsFrames(attr, times)


def clip_sets(mesh) -> dict:
    """The mesh prim's value clip sets (UsdClipsAPI's `clips` dictionary: name -> assetPaths, active, times,
    primPath, manifestAssetPath), empty when its points are not in value clips."""
    from pxr import Usd

    return dict(Usd.ClipsAPI(mesh.GetPrim()).GetClips() or {})


def frames_of(stage, mesh) -> tuple[list[float], PointsFrames | np.ndarray]:
    """The mesh's animation: its `points` samples, or, when it has none and is bound to blend shapes, the
    points blended from its UsdSkel blend shapes at each blendShapeWeights sample ([T, V, 3] float32).
    A broken skel binding is a FacegenError."""
    times, frames = points_samples(mesh)
    if times or not usd_skel.has_blendshapes(mesh):
        return times, frames
    rest = rest_points(mesh)
    if rest is None:
        raise FacegenError(f"mesh {mesh.GetPath()} has blend shapes but no points to apply them to")
    return usd_skel.blendshape_frames(stage, mesh, rest)


def rest_points(mesh) -> np.ndarray | None:
    """The default (non-animated) `points` value, which facegen writes as the rest pose."""
    from pxr import Usd

    value = mesh.GetPointsAttr().Get(Usd.TimeCode.Default())
    return None if value is None or len(value) == 0 else np.asarray(value, dtype=np.float32)


def stage_fps(stage) -> float | None:
    """The stage's timeCodesPerSecond when its root layer authors it (or framesPerSecond), else None."""
    layer = stage.GetRootLayer()
    if layer.HasTimeCodesPerSecond() or layer.HasFramesPerSecond():
        return float(stage.GetTimeCodesPerSecond())
    return None


def audio_file(sound) -> tuple[str, str]:
    """(authored asset path, resolved absolute path or '') of a SpatialAudio prim's filePath."""
    asset = sound.GetFilePathAttr().Get()
    if asset is None:
        return "", ""
    return asset.path, asset.resolvedPath


def read_audio_asset(resolved: str) -> tuple[np.ndarray, int]:
    """Read the audio a SpatialAudio prim resolves to: a file, or a file inside a .usdz package
    (`clip.usdz[clip.wav]`, read through USD's asset resolver); unreadable audio is a FacegenError."""
    from pxr import Ar

    if not Ar.IsPackageRelativePath(resolved):
        return load_audio(resolved)
    asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
    if asset is None:
        raise FacegenError(f"cannot open audio {resolved}: the package is incomplete, write it again")
    return load_audio(bytes(asset.GetBuffer()), what=f"audio {resolved}")


def read(path: str | os.PathLike, template: Mesh | None = None, fps: float | None = None) -> Animation:
    """Read a USD face animation: the mesh's faces, one frame per `points` time sample (or per
    blendShapeWeights sample, blended, for a blendshapes file), fps, audio.

    The fps is the stage's timeCodesPerSecond (`fps`, else 25, when it is not authored); asking for an
    fps the file contradicts is a FacegenError. With `template`, the file's topology must match it.
    """
    stage = open_stage(path)
    mesh = find_mesh(stage)
    if mesh is None:
        raise FacegenError(f"{path} has no UsdGeom.Mesh: pass a facegen USD animation")
    faces = mesh_faces(mesh)
    _, frames = frames_of(stage, mesh)
    if len(frames) == 0:
        raise FacegenError(f"{path}: mesh {mesh.GetPath()} has no points time samples: nothing to read")
    vertices = frames if isinstance(frames, np.ndarray) else None
    # into one array as they are read: a long clip is not held twice
    for i, frame in enumerate(() if vertices is not None else frames):
        if vertices is None:
            vertices = np.empty((len(frames), *frame.shape), np.float32)
        if frame.shape != vertices.shape[1:]:
            raise FacegenError(f"{path}: the points samples have different vertex counts: the file is broken")
        vertices[i] = frame
    file_fps = stage_fps(stage)
    if fps is not None and file_fps is not None and abs(file_fps - fps) > 1e-6:
        raise FacegenError(f"{path} is at {file_fps:g} fps but {fps:g} fps was asked: drop the frame rate or "
                           "resample", param="fps")
    rate = float(file_fps if file_fps is not None else fps if fps is not None else DEFAULT_FPS)
    if template is not None:
        check_topology(Mesh(vertices[0], faces), template.num_vertices, template.faces, f"{path}")
        face = Mesh(template.vertices, faces, template.regions)
    else:
        rest = rest_points(mesh)
        face = Mesh(vertices[0] if rest is None or rest.shape != vertices.shape[1:] else rest, faces)
    audio, sample_rate = None, 16000
    sound = find_audio(stage)
    if sound is not None:
        asset, resolved = audio_file(sound)
        if not resolved:
            raise FacegenError(f"{path} refers to audio {asset!r}, which is missing: put it beside the file")
        audio, sample_rate = read_audio_asset(resolved)
    info = stage.GetRootLayer().customLayerData.get("facegen", {})
    metadata = python_value(info.get("metadata", {})) if isinstance(info, dict) else {}
    head, pivot = usd_head(stage.GetPrimAtPath(ROOT_PATH), len(vertices))
    return Animation.from_mesh(face, vertices, rate, audio=audio, sample_rate=sample_rate, metadata=metadata,
                               head=head, head_pivot=pivot)

