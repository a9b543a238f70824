"""Track faces with MediaPipe Face Mesh: run by the faces venv's Python (`make faces-venv`), not facegen's.

    .venv-faces/bin/python benchmarks/real_faces_track.py OUT.npz INPUT [INPUT ...]

Each INPUT is a video file (decoded by OpenCV) or a .npy of RGB frames [T, H, W, 3] uint8 (facegen's render).
Both go through the same tracker, so real faces and facegen's face are measured alike. OUT.npz holds, per
input k, `lm{k}`: [T, 478, 3] float32 landmarks in pixels (x, y; z in x's pixel scale), NaN where no face was
found, and `size{k}`: (width, height).

Why a separate script and venv: mediapipe 0.10.14 is the last release that ships its face-landmark models
inside the wheel (later ones download them at run time), and it needs protobuf < 5, which the Ray extra of
facegen's own venv does not allow. It imports nothing of facegen; benchmarks/real_faces.py calls it.
"""

from __future__ import annotations

import sys

import numpy as np

N_LANDMARKS = 478  # 468 mesh points + 10 iris points (refine_landmarks)


def frames_of(path: str):
    """RGB frames [H, W, 3] uint8 of a video file or of a .npy frame stack, one at a time."""
    if path.endswith(".npy"):
        yield from np.load(path, mmap_mode="r")
        return
    import cv2

    cap = cv2.VideoCapture(path)
    if not cap.isOpened():
        raise SystemExit(f"cannot open video {path}")
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        yield cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
    cap.release()


def track(path: str) -> tuple[np.ndarray, tuple[int, int]]:
    """Landmarks [T, 478, 3] in pixels of the one face in `path`, each frame found afresh (static image mode).

    Why not the tracker's video mode, which starts each frame from the last one's face: on facegen's render it
    reads mouths open by up to 5 mm as closed (tracked vs geometric aperture r 0.77, median 0.15x, on GRID's
    bbaf2n animated), where frame by frame it follows them (r 0.90, 0.69x). On real GRID faces both modes
    agree (r 0.98-0.99 on 4 clips, medians within 1.00-1.16x)."""
    import mediapipe as mp

    rows, size = [], (0, 0)
    with mp.solutions.face_mesh.FaceMesh(
        static_image_mode=True,
        max_num_faces=1,
        refine_landmarks=True,
        min_detection_confidence=0.5,
        min_tracking_confidence=0.5,
    ) as mesh:
        for frame in frames_of(path):
            h, w = frame.shape[:2]
            size = (w, h)
            found = mesh.process(np.ascontiguousarray(frame)).multi_face_landmarks
            if not found:
                rows.append(np.full((N_LANDMARKS, 3), np.nan, np.float32))
                continue
            pts = np.array([(p.x, p.y, p.z) for p in found[0].landmark], np.float32)
            rows.append(pts * np.array([w, h, w], np.float32))
    return np.stack(rows) if rows else np.zeros((0, N_LANDMARKS, 3), np.float32), size


def main(argv: list[str]) -> None:
    if len(argv) < 2:
        raise SystemExit(__doc__)
    out, inputs = argv[0], argv[1:]
    arrays = {}
    for k, path in enumerate(inputs):
        lm, size = track(path)
        arrays[f"lm{k}"], arrays[f"size{k}"] = lm, np.array(size)
    np.savez_compressed(out, **arrays)


if __name__ == "__main__":
    main(sys.argv[1:])
