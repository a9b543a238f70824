"""The head's motion (facegen.head) read back from the files that carry it as a transform: USD's /Face
xformOps and glTF's Head node. The readers (usd.read, gltf.read) give it to Animation.head and head_pivot, so
`facegen render`, and a file read and written again, turn the head as the animation did."""

from __future__ import annotations

import numpy as np

from facegen.errors import FacegenError


def usd_head(root, frames: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The head's motion as usd._author_head writes it on `root` (the /Face prim): ([frames, 3] yaw, pitch,
    roll degrees at the frames' time codes, [3] pivot), or (None, None) for a still head."""
    turn = root.GetAttribute("xformOp:rotateZXY:head") if root else None
    move = root.GetAttribute("xformOp:translate:pivot") if root else None
    if not turn or not move or not turn.GetNumTimeSamples():
        return None, None
    values = np.array([turn.Get(float(t)) for t in range(frames)], np.float32)  # (pitch, yaw, roll)
    return values[:, [1, 0, 2]], np.array(move.Get(), np.float32)


def gltf_head(decoded: dict, frames: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The head's motion as gltf.build writes it (`decoded`: gltf.decode's): the rotation keys of the node
    "Head" whose child is the face node, as ([frames, 3] yaw, pitch, roll degrees, [3] pivot in mesh units),
    or (None, None) without one."""
    from scipy.spatial.transform import Rotation

    from facegen.head import angles_of

    doc, face = decoded["file"].doc, decoded["node"]
    head = next((i for i, n in enumerate(doc.nodes) if n.name == "Head" and face in (n.children or [])), None)
    if head is None:
        return None, None
    keys = next(((anim.samplers[ch.sampler].input, anim.samplers[ch.sampler].output)
                 for anim in doc.animations or [] for ch in anim.channels or []
                 if ch.target.node == head and ch.target.path == "rotation"), None)
    if keys is None:
        return None, None
    turns = decoded["file"].accessor(keys[1]).astype(np.float64).reshape(-1, 4)
    if len(turns) != frames:
        raise FacegenError(f"{decoded['file'].path}: the Head node has {len(turns)} rotation keys for "
                           f"{frames} frames: the file is broken")
    scale = float((decoded["scale"] or [1.0])[0])
    pivot = np.asarray(doc.nodes[head].translation or [0.0, 0.0, 0.0], np.float64) / scale
    return angles_of(Rotation.from_quat(turns).as_matrix()), pivot.astype(np.float32)
