"""glTF 2.0 (.glb binary, .gltf JSON + .bin): the face as one mesh with morph targets, animated weights.

Layout of a written file:

    scene 0        node "Face" (scale = meters_per_unit, default 0.2 like the USD writer: glTF is in
                   meters, the vertex data stays in the animation's units); with head motion (facegen.head)
                   node 1 "Head", its parent, at the head's pivot (Face translated back by it), whose
                   rotation is animated; a global KHR_audio_emitter emitter playing the clip's sound when
                   there is audio
    mesh "Face"    one triangle primitive: POSITION (the template: the neutral face, a real pose, which
                   static readers show), NORMAL, TEXCOORD_0 (exchange/surface.py's UVs, v down), COLOR_0
                   (the regions' colours, when the face names them: gltf_parts.py), indices
                   (uint16 when V < 65536), material 0; morph `targets` of POSITION and NORMAL offsets
                   (morph_targets.py, by `rig`): "pca" (default) a PCA of the clip's offsets, K the fewest
                   that keep the largest vertex error under `tolerance` x the face size (default 1e-3), or
                   `morph_targets` fixes K, or "all" = one target per frame (clips up to 300 frames), plus
                   a target "rest" whose weight is 1 in every frame; "arkit" the 52 ARKit blend shapes named
                   by their ARKit names, weights from the solver. Every weight lies in [0, 1] (Blender
                   clamps shape keys to that range). NORMAL offsets make the blended normals follow the
                   moving surface (least squares over the frames). mesh.weights = frame 0's weights;
                   mesh.extras.targetNames names the targets (three.js and Blender read it).
    material 0     "Face" (white base colour x COLOR_0) or, for a face without coloured regions, "Skin"
                   (base colour surface.SKIN_COLOR); metallic 0, roughness 0.6
    animation      "speech": a channel of the Face node's `weights`, LINEAR sampler, input times frame /
                   fps (0 .. (T-1)/fps), output T x K weights; with head motion a second, the Head node's
                   `rotation` (T unit quaternions) on the same times
    audio          KHR_audio_emitter (draft; in extensionsUsed only, so readers without it still load the
                   file): the clip as audio/mpeg in a bufferView, one source (autoPlay, no loop), one global
                   emitter on the scene. The MP3 is delay-compensated (exchange/mp3.py). The exact clip is
                   also written as a WAV beside the file (`out.wav`): Blender and most DCCs ignore the
                   extension and take the sidecar.
    parts          with parts (an Animation from the network): nodes LeftEye, RightEye, UpperTeeth,
                   LowerTeeth, Tongue, EyeSockets under "Face" with meshes, materials, channels: gltf_parts.py
    asset.extras   facegen: version, fps, frames, duration, rig, morphTargets (targets in the file),
                   tolerance, reconstructionError (largest vertex error / face size),
                   reconstructionErrorUnits, faceSize, metersPerUnit, lipErrorMm and faceErrorMm (arkit:
                   the fit's mean errors), audio (sampleRate, samples, bitrate, delayCompensated, sidecar),
                   metadata

POSITION accessors (base and targets) and the sampler input carry min/max. A `.gltf` keeps its binary data
in `out.bin` beside it. All files are written through temporary files: a failure leaves none of them.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from facegen import __version__
from facegen.animation import DEFAULT_FPS, Animation, check_animation
from facegen.atomic import atomic_path
from facegen.audio import load_audio
from facegen.errors import FacegenError
from facegen.exchange import mp3
from facegen.exchange.formats import by_module
from facegen.exchange.gltf_parts import add_parts, face_surface
from facegen.exchange.head_read import gltf_head
from facegen.exchange.morph_targets import normal_deltas, targets_as_written, writer_basis
from facegen.exchange.pca import MorphBasis
from facegen.exchange.surface import face_uvs
from facegen.exchange.wav import atomic_with_sidecar, sidecar_path
from facegen.face.mesh import Mesh, check_topology, vertex_normals

FORMAT = by_module(__name__)
DEFAULT_METERS_PER_UNIT = 0.2
AUDIO_EXTENSION = "KHR_audio_emitter"
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
FLOAT, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5123, 5125
_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def write(
    anim: Animation,
    path: str | os.PathLike,
    *,
    rig: str = "pca",
    morph_targets: int | str | None = None,
    tolerance: float | None = None,
    meters_per_unit: float = DEFAULT_METERS_PER_UNIT,
    write_audio: bool = True,
    audio_source: str | os.PathLike | None = None,
) -> list[Path]:
    """Write `anim` as .glb or .gltf (+ .bin) with its audio embedded and as a WAV sidecar.

    `rig`: "pca" or "arkit" (the 52 ARKit shapes; needs the face's rig regions). `morph_targets` (PCA):
    None (fewest targets within `tolerance` x face size; default tolerance 1e-3), a number, or "all".
    `audio_source`: the input audio file, kept (not overwritten) when it is the sidecar.
    Returns the files written: the glTF file, then the .bin (for .gltf), then the WAV (with audio).
    """
    check_animation(anim)
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FORMAT.extensions:
        raise FacegenError(f"{path} is not a glTF file name: use one of {', '.join(FORMAT.extensions)}")
    if not meters_per_unit > 0:
        raise FacegenError(f"meters per unit must be positive, got {meters_per_unit}")
    basis = writer_basis(anim, rig, morph_targets, tolerance)
    audio = anim.audio if write_audio and anim.audio is not None and len(anim.audio) else None
    sound = mp3.encode(audio, anim.sample_rate) if audio is not None else None
    bin_path = path.with_suffix(".bin")
    gltf, blob = build(anim, basis, sound, meters_per_unit, wav_name=sidecar_path(path).name if sound
                       else None)
    with atomic_with_sidecar(path, audio, anim.sample_rate, audio_source) as (tmp, wav):
        if suffix == ".glb":
            gltf.set_binary_blob(blob)
            gltf.save_binary(str(tmp))
        else:
            gltf.buffers[0].uri = bin_path.name
            tmp.write_text(gltf.to_json(separators=(",", ":")))
            with atomic_path(bin_path) as tmp_bin:  # joins the transaction: renamed with the .gltf
                tmp_bin.write_bytes(blob)
    return [path] + ([bin_path] if suffix == ".gltf" else []) + ([wav] if wav is not None else [])


def build(
    anim: Animation, basis: MorphBasis, sound: tuple[bytes, dict] | None, meters_per_unit: float,
    wav_name: str | None = None,
):
    """The pygltflib.GLTF2 document and its binary buffer for `anim` stored with `basis`."""
    import pygltflib as g

    blob = _Blob()
    accessors: list = []

    def accessor(data: np.ndarray, kind: str, target: int | None, with_bounds: bool = False) -> int:
        array = np.ascontiguousarray(data)
        view = blob.add(array.tobytes(), target)
        component = {np.dtype(np.float32): FLOAT, np.dtype(np.uint16): UNSIGNED_SHORT,
                     np.dtype(np.uint32): UNSIGNED_INT}[array.dtype]
        count = array.shape[0] if kind != "SCALAR" else array.size
        bounds = {}
        if with_bounds:
            flat = array.reshape(count, -1)
            bounds = {"min": flat.min(0).astype(float).tolist(), "max": flat.max(0).astype(float).tolist()}
        accessors.append(g.Accessor(bufferView=view, componentType=component, count=int(count), type=kind,
                                    **bounds))
        return len(accessors) - 1

    base = np.asarray(anim.template, dtype=np.float32)
    faces = np.asarray(anim.faces)
    names, offsets, weights = targets_as_written(basis)
    index_type = np.uint16 if len(base) < 65536 else np.uint32
    index_component = UNSIGNED_SHORT if index_type is np.uint16 else UNSIGNED_INT
    position = accessor(base, "VEC3", ARRAY_BUFFER, with_bounds=True)
    normal = accessor(vertex_normals(base, faces), "VEC3", ARRAY_BUFFER)
    uv = face_uvs(base) * np.float32([1, -1]) + np.float32([0, 1])  # glTF's v runs down
    texcoord = accessor(uv, "VEC2", ARRAY_BUFFER)
    indices = accessor(faces.astype(index_type).reshape(-1), "SCALAR", ELEMENT_ARRAY_BUFFER, with_bounds=True)

    def target_accessor(values: np.ndarray) -> int:
        """A morph target's offsets: sparse (on zeros) when that is smaller than dense; with min/max."""
        moving = np.flatnonzero(np.any(values != 0, axis=1))
        if len(moving) * (np.dtype(index_type).itemsize + 12) >= len(values) * 12:
            return accessor(values, "VEC3", ARRAY_BUFFER, with_bounds=True)
        if len(moving) == 0:
            moving = np.zeros(1, np.int64)  # a sparse accessor needs at least one entry
        ids = blob.add(moving.astype(index_type).tobytes(), None)
        data = blob.add(np.ascontiguousarray(values[moving], np.float32).tobytes(), None)
        sparse = g.Sparse(count=len(moving),
                          indices=g.AccessorSparseIndices(bufferView=ids, componentType=index_component),
                          values=g.AccessorSparseValues(bufferView=data))
        accessors.append(g.Accessor(componentType=FLOAT, count=len(values), type="VEC3", sparse=sparse,
                                    byteOffset=None, min=values.min(0).astype(float).tolist(),
                                    max=values.max(0).astype(float).tolist()))
        return len(accessors) - 1

    normal_offsets = normal_deltas(base, faces, offsets, weights)
    targets = [{"POSITION": target_accessor(p), "NORMAL": target_accessor(n)}
               for p, n in zip(offsets, normal_offsets, strict=True)]
    times = np.arange(anim.num_frames, dtype=np.float64) / float(anim.fps)
    time_input = accessor(times.astype(np.float32), "SCALAR", None, with_bounds=True)
    weight_output = accessor(weights.reshape(-1), "SCALAR", None)

    skin, colors = face_surface(anim, accessor)  # gltf_parts.py: the regions' colours as COLOR_0
    primitive = g.Primitive(attributes=g.Attributes(POSITION=position, NORMAL=normal, TEXCOORD_0=texcoord,
                                                    COLOR_0=colors),
                            indices=indices, mode=g.TRIANGLES, targets=targets, material=0)
    mesh = g.Mesh(name="Face", primitives=[primitive], weights=weights[0].astype(float).tolist(),
                  extras={"targetNames": names})
    node = g.Node(name="Face", mesh=0, scale=[float(meters_per_unit)] * 3)
    nodes = [node]
    samplers = [g.AnimationSampler(input=time_input, output=weight_output, interpolation="LINEAR")]
    channels = [g.AnimationChannel(sampler=0, target=g.AnimationChannelTarget(node=0, path="weights"))]
    if anim.head is not None:  # the head turns about its pivot: a parent node's rotation channel
        from facegen.head import quaternions

        pivot = np.asarray(anim.head_pivot, np.float64) * meters_per_unit
        turns = quaternions(anim.head)
        node.translation = (-pivot).tolist()
        nodes.append(g.Node(name="Head", children=[0], translation=pivot.tolist(),
                            rotation=turns[0].astype(float).tolist()))
        samplers.append(g.AnimationSampler(input=time_input, output=accessor(turns, "VEC4", None),
                                           interpolation="LINEAR"))
        channels.append(g.AnimationChannel(sampler=1,
                                           target=g.AnimationChannelTarget(node=1, path="rotation")))
    scene = g.Scene(name="Scene", nodes=[len(nodes) - 1])
    meshes, materials = [mesh], [skin]
    add_parts(anim, accessor, nodes, meshes, materials, samplers, channels, time_input)  # gltf_parts.py
    animation = g.Animation(name="speech", samplers=samplers, channels=channels)
    extras = {
        "facegen": {
            "version": __version__,
            "fps": float(anim.fps),
            "frames": int(anim.num_frames),
            "duration": float(anim.duration),
            "rig": basis.rig,
            "morphTargets": len(names),
            "tolerance": basis.tolerance,
            "reconstructionError": float(basis.relative_error),
            "reconstructionErrorUnits": float(basis.max_error),
            "faceSize": float(basis.size),
            "metersPerUnit": float(meters_per_unit),
            **({} if basis.lip_error_mm is None else {"lipErrorMm": basis.lip_error_mm}),
            **({} if basis.face_error_mm is None else {"faceErrorMm": basis.face_error_mm}),
            "metadata": _jsonable(anim.metadata),
        }
    }
    gltf = g.GLTF2(
        asset=g.Asset(version="2.0", generator=f"facegen {__version__}", extras=extras),
        scene=0, scenes=[scene], nodes=nodes, meshes=meshes, materials=materials, animations=[animation],
        accessors=accessors,
    )
    if sound is not None:
        data, info = sound
        view = blob.add(data, None)
        gltf.extensionsUsed = [AUDIO_EXTENSION]
        gltf.extensions = {
            AUDIO_EXTENSION: {
                "audio": [{"bufferView": view, "mimeType": "audio/mpeg"}],
                "sources": [{"name": "speech", "audio": 0, "autoPlay": True, "loop": False, "gain": 1.0}],
                "emitters": [{"name": "speech", "type": "global", "gain": 1.0, "sources": [0]}],
            }
        }
        scene.extensions = {AUDIO_EXTENSION: {"emitters": [0]}}
        extras["facegen"]["audio"] = dict(info, sidecar=wav_name)
    gltf.bufferViews = blob.views
    data = blob.data()
    gltf.buffers = [g.Buffer(byteLength=len(data))]
    return gltf, data


class _Blob:
    """The binary buffer being built: 4-byte aligned bufferViews."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.length = 0
        self.views: list = []

    def add(self, data: bytes, target: int | None) -> int:
        import pygltflib as g

        pad = (-self.length) % 4
        if pad:
            self.parts.append(b"\0" * pad)
            self.length += pad
        self.views.append(g.BufferView(buffer=0, byteOffset=self.length, byteLength=len(data), target=target))
        self.parts.append(data)
        self.length += len(data)
        return len(self.views) - 1

    def data(self) -> bytes:
        pad = (-self.length) % 4
        return b"".join(self.parts) + b"\0" * pad


def _jsonable(values: dict) -> dict:
    """The JSON-serialisable part of a metadata dict (numpy values become Python ones)."""
    out = {}
    for key, value in values.items():
        try:
            out[str(key)] = json.loads(json.dumps(value, default=_plain))
        except (TypeError, ValueError):
            continue
    return out


def _plain(value):
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(type(value).__name__)


# ---- reading -----------------------------------------------------------------------------------------


class GltfFile:
    """A loaded glTF document with its binary buffers, and accessor decoding (incl. sparse)."""

    def __init__(self, path: str | os.PathLike) -> None:
        import pygltflib as g

        self.path = Path(path)
        if not self.path.is_file():
            raise FacegenError(f"glTF file {self.path} does not exist: pass an existing .glb or .gltf file")
        try:
            self.doc = g.GLTF2().load(str(self.path))
        except Exception as exc:  # pygltflib raises many types for bad files
            raise FacegenError(f"cannot read {self.path} as glTF ({exc}): pass a valid .glb or .gltf "
                               "file") from exc
        if self.doc is None:
            raise FacegenError(f"cannot read {self.path} as glTF: pass a valid .glb or .gltf file")
        self._buffers: dict[int, bytes] = {}

    def buffer(self, index: int) -> bytes:
        if index not in self._buffers:
            buf = self.doc.buffers[index]
            if buf.uri is None:
                data = self.doc.binary_blob()
            elif buf.uri.startswith("data:"):
                data = self.doc.decode_data_uri(buf.uri)
            else:
                file = self.path.parent / buf.uri
                if not file.is_file():
                    raise FacegenError(f"{self.path} needs its buffer file {file}, which is missing: put it "
                                       "beside it")
                data = file.read_bytes()
            if data is None or len(data) < (buf.byteLength or 0):
                raise FacegenError(f"{self.path}: buffer {index} is shorter than its byteLength: the file is "
                                   "broken")
            self._buffers[index] = data
        return self._buffers[index]

    def view_bytes(self, index: int) -> bytes:
        view = self.doc.bufferViews[index]
        data = self.buffer(view.buffer)
        start = view.byteOffset or 0
        return data[start:start + view.byteLength]

    def accessor(self, index: int) -> np.ndarray:
        """Accessor `index` as a [count, width] (or [count] for scalars) numpy array."""
        acc = self.doc.accessors[index]
        dtype = np.dtype(_DTYPES[acc.componentType])
        width = _WIDTH[acc.type]
        if acc.bufferView is None:
            out = np.zeros((acc.count, width), dtype)
        else:
            view = self.doc.bufferViews[acc.bufferView]
            raw = self.view_bytes(acc.bufferView)
            stride = view.byteStride or dtype.itemsize * width
            start = acc.byteOffset or 0
            needed = start + stride * (acc.count - 1) + dtype.itemsize * width if acc.count else 0
            if needed > len(raw):
                raise FacegenError(f"{self.path}: accessor {index} runs past its bufferView: the file is "
                                   "broken")
            out = np.ndarray((acc.count, width), dtype, buffer=raw, offset=start, strides=(stride,
                                                                                           dtype.itemsize))
            out = out.copy()
        if acc.sparse is not None and acc.sparse.count:
            sp = acc.sparse
            idx_dtype = np.dtype(_DTYPES[sp.indices.componentType])
            ids = np.frombuffer(self.view_bytes(sp.indices.bufferView), idx_dtype, sp.count,
                                sp.indices.byteOffset or 0)
            values = np.frombuffer(self.view_bytes(sp.values.bufferView), dtype, sp.count * width,
                                   sp.values.byteOffset or 0)
            out[ids.astype(np.int64)] = values.reshape(sp.count, width)
        return out.reshape(-1) if width == 1 else out

    def facegen_info(self) -> dict:
        extras = self.doc.asset.extras if self.doc.asset is not None else None
        info = extras.get("facegen") if isinstance(extras, dict) else None
        return info if isinstance(info, dict) else {}

    def mp3_audio(self) -> bytes | None:
        """The embedded KHR_audio_emitter audio/mpeg bytes, or None."""
        ext = (self.doc.extensions or {}).get(AUDIO_EXTENSION)
        if not isinstance(ext, dict):
            return None
        for item in ext.get("audio", []):
            if item.get("bufferView") is not None and item.get("mimeType") == "audio/mpeg":
                return self.view_bytes(int(item["bufferView"]))
        return None


def find_animated_mesh(doc) -> tuple[int, int]:
    """(node index, mesh index) of the first node whose mesh has morph targets and animated weights."""
    animated = {
        ch.target.node for anim in doc.animations or [] for ch in anim.channels or []
        if ch.target.path == "weights"
    }
    for i, node in enumerate(doc.nodes or []):
        if node.mesh is not None and i in animated:
            return i, node.mesh
    for i, node in enumerate(doc.nodes or []):
        if node.mesh is not None:
            return i, node.mesh
    raise FacegenError("the glTF file has no mesh node: pass a facegen glTF animation")


def weight_track(doc, node: int) -> tuple[int, int, str] | None:
    """(input accessor, output accessor, interpolation) of the `weights` channel animating `node`."""
    for anim in doc.animations or []:
        for ch in anim.channels or []:
            if ch.target.node == node and ch.target.path == "weights":
                sampler = anim.samplers[ch.sampler]
                return sampler.input, sampler.output, sampler.interpolation or "LINEAR"
    return None


def decode(path: str | os.PathLike) -> dict:
    """Everything `read` and `facegen validate` need, decoded: base [V,3], targets [K,V,3], times [T],
    weights [T,K], faces [F,3], fps (asset extras, else from the times), info, the targets' names
    (mesh.extras.targetNames, else none), the file object."""
    file = GltfFile(path)
    doc = file.doc
    node, mesh_index = find_animated_mesh(doc)
    mesh = doc.meshes[mesh_index]
    if len(mesh.primitives) != 1:
        raise FacegenError(f"{path}: mesh {mesh_index} has {len(mesh.primitives)} primitives, facegen writes "
                           "one")
    prim = mesh.primitives[0]
    if prim.attributes.POSITION is None:
        raise FacegenError(f"{path}: the mesh has no POSITION attribute")
    base = file.accessor(prim.attributes.POSITION).astype(np.float32)
    if prim.indices is None or (prim.mode not in (None, 4)):
        raise FacegenError(f"{path}: the mesh is not an indexed triangle list")
    faces = file.accessor(prim.indices).astype(np.int64).reshape(-1, 3).astype(np.int32)
    targets = np.stack([file.accessor(t["POSITION"]) for t in prim.targets]).astype(np.float32) \
        if prim.targets else np.zeros((0,) + base.shape, np.float32)
    track = weight_track(doc, node)
    info = file.facegen_info()
    if track is None:
        times = np.zeros(1, np.float32)
        weights = np.asarray([mesh.weights or [0.0] * len(targets)], np.float32)
        interpolation = "STEP"
    else:
        times = file.accessor(track[0]).astype(np.float64)
        values = file.accessor(track[1]).astype(np.float32)
        interpolation = track[2]
        per_key = 3 if interpolation == "CUBICSPLINE" else 1
        K = len(targets)
        if K == 0 or values.size != len(times) * K * per_key:
            raise FacegenError(f"{path}: {values.size} weight values for {len(times)} keys and {K} targets")
        weights = values.reshape(len(times), per_key, K)[:, per_key // 2]
    fps = info.get("fps")
    if not isinstance(fps, int | float) or fps <= 0:
        steps = np.diff(times)
        fps = float(1.0 / np.median(steps)) if len(steps) and np.median(steps) > 0 else None
    scale = doc.nodes[node].scale
    names = (mesh.extras or {}).get("targetNames") if isinstance(mesh.extras, dict) else None
    return {
        "file": file, "node": node, "mesh": mesh_index, "base": base, "targets": targets, "times": times,
        "weights": weights, "faces": faces, "fps": fps, "info": info, "interpolation": interpolation,
        "scale": scale, "names": [str(n) for n in names] if isinstance(names, list) else [],
    }


def reconstruct(decoded: dict) -> np.ndarray:
    """The [T, V, 3] float32 positions at the animation's keys: base + weights @ targets."""
    base, targets, weights = decoded["base"], decoded["targets"], decoded["weights"]
    if len(targets) == 0:
        return np.repeat(base[None], len(weights), axis=0)
    flat = weights.astype(np.float32) @ targets.reshape(len(targets), -1)
    return (flat.reshape(len(weights), -1, 3) + base[None]).astype(np.float32)


def read(path: str | os.PathLike, template: Mesh | None = None, fps: float | None = None) -> Animation:
    """Read a glTF face animation: positions at each key (base + weights @ targets), faces, fps, audio
    (the WAV sidecar when present, else the embedded MP3). With `template`, topology must match it."""
    decoded = decode(path)
    vertices = reconstruct(decoded)
    file_fps = decoded["fps"]
    if fps is not None and file_fps is not None and abs(file_fps - fps) > 1e-3:
        raise FacegenError(f"{path} is at {file_fps:g} fps but {fps:g} fps was asked: drop the frame rate or "
                           "resample", param="fps")
    rate = float(file_fps if file_fps is not None else fps if fps is not None else DEFAULT_FPS)
    faces = decoded["faces"]
    if template is not None:
        check_topology(Mesh(vertices[0], faces), template.num_vertices, template.faces, f"{path}")
        face = Mesh(template.vertices, faces, template.regions)
    else:
        face = Mesh(decoded["base"], faces)
    audio, sample_rate = None, 16000
    wav = sidecar_path(path)
    if wav.is_file():
        audio, sample_rate = load_audio(wav)
    else:
        data = decoded["file"].mp3_audio()
        if data is not None:
            audio, sample_rate = mp3.decode(data)
    metadata = decoded["info"].get("metadata", {})
    head, pivot = gltf_head(decoded, len(vertices))
    return Animation.from_mesh(face, vertices, rate, audio=audio, sample_rate=sample_rate,
                               metadata=metadata if isinstance(metadata, dict) else {}, head=head,
                               head_pivot=pivot)

