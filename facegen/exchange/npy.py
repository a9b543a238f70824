"""NumPy .npy: vertex positions as a [T, 3V] float32 array (the FaceFormer/CodeTalker layout).

Row t is frame t, columns x0 y0 z0 x1 y1 z1 ...; faces and fps are not stored (the template mesh and
`--fps`, 25 by default, supply them). The audio goes beside the file as a WAV sidecar (`out.wav`), the
head's motion (facegen.head) as `out.head.npy`, [T, 3] float32 (yaw, pitch, roll) degrees.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from facegen.animation import DEFAULT_FPS, Animation, check_animation
from facegen.atomic import Transaction
from facegen.audio import load_audio
from facegen.errors import FacegenError
from facegen.exchange.wav import atomic_with_sidecar, sidecar_path
from facegen.face.mesh import Mesh


def write(
    anim: Animation,
    path: str | os.PathLike,
    *,
    write_audio: bool = True,
    audio_source: str | os.PathLike | None = None,
) -> list[Path]:
    """Write the frames as [T, 3V] float32 and, when there is audio, a WAV sidecar; return the files.

    `audio_source` is the input audio file: when it is the sidecar itself it is kept, not overwritten.
    """
    check_animation(anim)
    path = Path(path)
    audio = anim.audio if write_audio and anim.audio is not None and len(anim.audio) else None
    with atomic_with_sidecar(path, audio, anim.sample_rate, audio_source) as (tmp, wav), open(tmp, "wb") as f:
        shape = (anim.num_frames, 3 * anim.num_vertices)  # the header np.save writes, then the frames
        np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": shape})
        for _, block in anim.frame_blocks():
            f.write(np.ascontiguousarray(block, dtype="<f4").data)
            del block  # before the next block is made: one block of frames alive, not two
        if anim.head is not None:  # beside it, so the research layout stays [T, 3V]
            with Transaction() as transaction, open(transaction.file(head_path(path)), "wb") as h:
                np.save(h, np.asarray(anim.head, "<f4"))
    return [path, *([] if wav is None else [wav]), *([] if anim.head is None else [head_path(path)])]


def head_path(path: str | os.PathLike) -> Path:
    """Where the head's motion of the .npy `path` goes: NAME.head.npy, [T, 3] float32 (yaw, pitch, roll)
    degrees (facegen.head)."""
    path = Path(path)
    return path.with_name(path.stem + ".head.npy")


def load_frames(path: str | os.PathLike) -> np.ndarray:
    """The raw [T, 3V] array of a .npy file (no pickles); unreadable files are a FacegenError."""
    path = Path(path)
    if not path.is_file():
        raise FacegenError(f"file {path} does not exist: pass an existing .npy file")
    try:  # memory-mapped first: a header promising more than the file holds is refused without allocating it
        data = np.load(path, allow_pickle=False, mmap_mode="r")
    # a malformed header raises ValueError, SyntaxError, EOFError, ... (no pickles run)
    except Exception as exc:
        raise FacegenError(f"cannot read {path} as .npy ({type(exc).__name__}: {exc}): pass a [T, 3V] float "
                           "array file") from exc
    if data.ndim != 2 or data.shape[0] == 0 or data.shape[1] == 0 or data.shape[1] % 3:
        raise FacegenError(f"{path} has shape {list(data.shape)}, expected [T, 3V]: pass a vertex array file")
    if not np.issubdtype(data.dtype, np.floating):
        raise FacegenError(f"{path} holds {data.dtype} values, expected floats: pass a vertex array file")
    return np.array(data)


def read(path: str | os.PathLike, template: Mesh | None = None, fps: float | None = None) -> Animation:
    """Read a [T, 3V] .npy file with the template's faces; the WAV sidecar beside it becomes the audio."""
    if template is None:
        raise FacegenError(
            f"{Path(path).name} stores only vertex positions: pass the template mesh", param="template"
        )
    data = load_frames(path)
    num_vertices = data.shape[1] // 3
    if num_vertices != template.num_vertices:
        raise FacegenError(
            f"{path} has {num_vertices} vertices per frame but the template has {template.num_vertices}: "
            "pass the template the file was made with"
        )
    audio, sample_rate = None, 16000
    wav = sidecar_path(path)
    if wav.is_file():
        audio, sample_rate = load_audio(wav)
    return Animation.from_mesh(
        template, data.reshape(len(data), num_vertices, 3).astype(np.float32),
        float(fps if fps is not None else DEFAULT_FPS), audio=audio, sample_rate=sample_rate,
    )
