"""The library entry point: speech (audio + words) → face animation."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facegen.animation import Animation
from facegen.audio import check_speech, load_audio, mel_features, num_frames
from facegen.bundle import Bundle, load_bundle
from facegen.errors import FacegenError
from facegen.mesh import Mesh, check_topology, read_mesh

Progress = Callable[[str], None]
LONG_INPUT_SECONDS = 20.0  # stage-by-stage progress is reported for clips at least this long


def _quiet(_: str) -> None:
    pass


def get_words(
    samples: np.ndarray,
    sr: int,
    *,
    text: str | None = None,
    alignment: str | os.PathLike | None = None,
    progress: Progress = _quiet,
    warn: Progress = _quiet,
) -> tuple[list, str]:
    """Word timings for the clip and where they came from (alignment file, forced alignment, recognition)."""
    from facegen import align

    duration = len(samples) / sr
    if alignment is not None:
        return align.read_alignment(alignment, duration=duration), "alignment file"
    if text is not None:
        if not text.strip():
            raise FacegenError("the transcript is empty: pass the words spoken with --text or --text-file")
        progress("aligning the transcript to the speech (pocketsphinx)")
        return align.align(samples, sr, text), "forced alignment"
    warn("no transcript given: recognising the words with pocketsphinx (lower quality than with a transcript; "
         "pass --text, --text-file or --alignment for better upper-face motion)")
    return align.recognize(samples, sr), "speech recognition"


def resolve_template(bundle: Bundle, template: str | os.PathLike | Mesh | None) -> Mesh:
    """The bundle's template, or a user mesh of the same topology (refused otherwise)."""
    if template is None:
        return bundle.template
    mesh = template if isinstance(template, Mesh) else read_mesh(template)
    check_topology(mesh, bundle.template.num_vertices, bundle.template.faces, f"template {template}")
    return Mesh(mesh.vertices, bundle.template.faces, bundle.template.regions)


def predict_offsets(bundle: Bundle, mel: np.ndarray, text: np.ndarray | None, speaker: int) -> np.ndarray:
    """Run the network: mel [T,n_mels], text [T,D] or None → offsets [T,V,3] float32."""
    import torch

    from facegen.model import one_hot

    cfg = bundle.config
    with torch.inference_mode():
        mel_t = torch.from_numpy(mel)[None]
        text_t = None
        if cfg.uses_text:
            if text is None:
                text = np.zeros((mel.shape[0], cfg.text_dim), np.float32)
            text_t = torch.from_numpy(np.ascontiguousarray(text, np.float32))[None]
        out = bundle.model(mel_t, text_t, one_hot(speaker, cfg.num_speakers))
    return out[0].numpy()


def animate(
    audio: str | os.PathLike,
    *,
    text: str | None = None,
    alignment: str | os.PathLike | None = None,
    no_text: bool = False,
    speaker: str | int | None = None,
    bundle: Bundle | str | os.PathLike | None = None,
    template: str | os.PathLike | Mesh | None = None,
    text_model: str | None = None,
    progress: Progress = _quiet,
    warn: Progress = _quiet,
) -> Animation:
    """Animate the face for one speech clip.

    Word timings come from `alignment` (a file), else from forced alignment of `text`, else from speech
    recognition; `no_text=True` feeds zero text features instead. `bundle` is a loaded Bundle or a path
    (None: the built-in default model). `progress` receives stage messages for long clips (≥ 20 s),
    `warn` receives notes the user should always see.
    """
    if not isinstance(bundle, Bundle):
        bundle = load_bundle(bundle)
    spk = bundle.speaker_index(speaker)
    mesh = resolve_template(bundle, template)
    samples, sr = load_audio(audio)
    cfg = bundle.features
    check_speech(samples, sr, cfg.fps, name=f"audio file {audio}")
    T = num_frames(len(samples) / sr, cfg.fps)
    if len(samples) / sr < LONG_INPUT_SECONDS:
        progress = _quiet

    words: list = []
    source = "none (--no-text)"
    text_feats = None
    if bundle.config.uses_text and not no_text:
        words, source = get_words(samples, sr, text=text, alignment=alignment, progress=progress, warn=warn)
        from facegen.text import load_text_backend, text_features

        progress(f"text features ({bundle.text_backend}) for {len(words)} words")
        backend = load_text_backend(bundle.text_backend, text_model)
        if backend.dim != bundle.config.text_dim:
            raise FacegenError(
                f"text model {backend.id} gives {backend.dim}-d features but the model was trained on "
                f"{bundle.config.text_dim}-d ({bundle.text_backend}): pass the matching --text-model"
            )
        text_feats = text_features(words, backend, T, cfg.fps)

    progress(f"audio features and inference for {T} frames")
    mel = mel_features(samples, sr, cfg, bundle.mel_filters)
    offsets = predict_offsets(bundle, mel, text_feats, spk)
    vertices = mesh.vertices[None].astype(np.float32) + offsets
    return Animation(
        vertices=vertices,
        faces=mesh.faces,
        fps=cfg.fps,
        template=mesh.vertices,
        audio=samples,
        sample_rate=sr,
        regions=dict(mesh.regions),
        metadata={
            "source_audio": Path(audio).name,
            "model": bundle.path.name if bundle.path else "in-memory",
            "model_fingerprint": bundle.fingerprint,
            "speaker": bundle.speakers[spk],
            "words": [{"word": w.text, "start": round(w.start, 4), "end": round(w.end, 4)} for w in words],
            "word_timing": source,
        },
    )
