"""The library entry point: speech (audio + words) → face animation — the one pipeline every command runs.

(Named pipeline, not animate, so that `facegen.animate` stays the function of the package API.)
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facegen.align_ahead import AlignAhead, Aligned
from facegen.animation import Animation
from facegen.audio import check_speech, load_audio, mel_features, num_frames
from facegen.bundle import Bundle, load_bundle
from facegen.errors import FacegenError
from facegen.inference import FrameStream, predict_frames
from facegen.mesh import Mesh, check_topology, read_mesh
from facegen.runtime import PROFILE, Say, select_device, silent

LONG_INPUT_SECONDS = 20.0  # stage-by-stage progress is reported for clips at least this long


def get_words(
    samples: np.ndarray,
    sr: int,
    *,
    text: str | None = None,
    alignment: str | os.PathLike | None = None,
    progress: Say = silent,
    warn: Say = silent,
    ahead: AlignAhead | Aligned | None = None,
) -> tuple[list, str]:
    """Word timings for the clip and where they came from (alignment file, forced alignment, recognition);
    `ahead`: the forced alignment of `text` already started in a process of its own (align_ahead.py)."""
    from facegen import align
    from facegen.words import read_alignment

    duration = len(samples) / sr
    if alignment is not None:
        return read_alignment(alignment, duration=duration), "alignment file"
    if text is not None:
        if not text.strip():
            raise FacegenError("the transcript is empty: pass the words spoken with --text or --text-file")
        progress("aligning the transcript to the speech (pocketsphinx)")
        return _forced(samples, sr, text, ahead, with_phones=False)[0], "forced alignment"
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


@dataclass
class Clip:
    """A clip's network inputs and what its Animation needs, before inference."""

    audio_name: str
    samples: np.ndarray
    sample_rate: int
    mel: np.ndarray  # [T, n_mels]
    text_features: np.ndarray | None  # [T, text_dim] or None (no text)
    words: list
    word_timing: str
    speaker: int
    mesh: Mesh
    phones: np.ndarray | None = None  # [T, P] one-hot (models with a phone stream)

    @property
    def num_frames(self) -> int:
        return int(self.mel.shape[0])


def prepare_clip(
    audio: str | os.PathLike,
    *,
    bundle: Bundle,
    text: str | None = None,
    alignment: str | os.PathLike | None = None,
    no_text: bool = False,
    speaker: str | int | None = None,
    template: str | os.PathLike | Mesh | None = None,
    text_model: str | None = None,
    progress: Say = silent,
    warn: Say = silent,
    ahead: AlignAhead | Aligned | None = None,
    meanwhile: Callable[[], object] | None = None,
) -> Clip:
    """Everything before the network: audio, word timings, text and audio features (see `animate`);
    `ahead`: the forced alignment of `text` already running in a process of its own, or done (align_ahead.py).
    While that alignment still runs, the transcript's word vectors are computed (they need the words, not their
    times) and `meanwhile` is called (e.g. to import the writer's libraries)."""
    spk = bundle.speaker_index(speaker)
    mesh = resolve_template(bundle, template)
    with PROFILE.stage("audio"):
        samples, sr = load_audio(audio)
    cfg = bundle.features
    check_speech(samples, sr, cfg.fps, name=f"audio file {audio}")
    T = num_frames(len(samples) / sr, cfg.fps)
    if len(samples) / sr < LONG_INPUT_SECONDS:
        progress = silent
    with PROFILE.stage("audio_features"):  # before the words: done while an alignment started ahead runs
        mel = mel_features(samples, sr, cfg, bundle.mel_filters)

    words: list = []
    source = "none (--no-text)"
    text_feats = phone_feats = None
    uses_text = bundle.config.uses_text and not no_text
    early: tuple[list[str], np.ndarray] | None = None  # the transcript's words and their vectors
    if ahead is not None and not ahead.ready():  # work that needs no word times, while they are found
        if meanwhile is not None:
            with PROFILE.stage("while_aligning"):
                meanwhile()
        if uses_text:
            from facegen.words import normalize_transcript

            backend = _text_backend(bundle, text_model)
            with PROFILE.stage("text_features"):
                names = [word for word, _ in normalize_transcript(text)]
                early = names, backend.word_vectors(names)
    if bundle.config.n_phones:
        with PROFILE.stage("alignment"):
            words, source, phone_feats = _words_and_phones(samples, sr, T, cfg.fps, text=text, alignment=alignment,
                                                           no_text=no_text, warn=warn, ahead=ahead)
    if uses_text:
        if not bundle.config.n_phones:
            with PROFILE.stage("alignment"):
                words, source = get_words(samples, sr, text=text, alignment=alignment, progress=progress,
                                          warn=warn, ahead=ahead)
        from facegen.text import frame_features, text_features

        progress(f"text features ({bundle.text_backend}) for {len(words)} words")
        if early is not None and early[0] == [w.text for w in words]:
            text_feats = frame_features(words, early[1], T, cfg.fps)
        else:
            backend = _text_backend(bundle, text_model)
            with PROFILE.stage("text_features"):
                text_feats = text_features(words, backend, T, cfg.fps)

    progress(f"inference for {T} frames")
    return Clip(Path(audio).name, samples, sr, mel, text_feats, words, source, spk, mesh, phone_feats)


def _text_backend(bundle: Bundle, text_model: str | None):
    """The bundle's text model (`text_model`: where its files are), checked against the bundle."""
    from facegen.text import check_text_dim, load_text_backend

    with PROFILE.stage("text_model_load"):
        backend = load_text_backend(bundle.text_backend, text_model)
    check_text_dim(backend, bundle.config.text_dim, bundle.text_backend)
    return backend


def _forced(samples: np.ndarray, sr: int, text: str, ahead: AlignAhead | Aligned | None,
            with_phones: bool) -> tuple[list, list | None]:
    """Forced alignment of `text` (words, and phones if `with_phones`): the answer of the process started
    ahead, else aligned here (also when that process gave no answer)."""
    from facegen import align

    found = ahead.result() if ahead is not None else None
    if found is not None:
        return found
    if with_phones:
        return align.align_phones(samples, sr, text)
    return align.align(samples, sr, text), None


def _words_and_phones(samples: np.ndarray, sr: int, num_frames: int, fps: float, *, text: str | None,
                      alignment, no_text: bool, warn: Say,
                      ahead: AlignAhead | Aligned | None = None) -> tuple[list, str, np.ndarray]:
    """Words and per-frame phones for a model with a phone stream: pocketsphinx's phone alignment of the
    transcript, the phones of an alignment file (facegen align --phones), or without a transcript (also with
    --no-text, which only drops the text features) the phone alignment of the recognised words."""
    from facegen.phones import phone_frames, silence
    from facegen.words import read_alignment, read_phones

    if alignment is not None:
        words = read_alignment(alignment, duration=len(samples) / sr)
        phones = read_phones(alignment)
        if phones is None:
            raise FacegenError(f"this model needs phone timings but {alignment} has none: write it with "
                               "`facegen align --phones`, or pass --text")
        return words, "alignment file", phone_frames(phones, num_frames, fps)
    if text is not None and not no_text:
        if not text.strip():
            raise FacegenError("the transcript is empty: pass the words spoken with --text or --text-file")
        words, phones = _forced(samples, sr, text, ahead, with_phones=True)
        return words, "forced alignment", phone_frames(phones, num_frames, fps)
    from facegen import align

    # no transcript: the recogniser's words, force-aligned again for their phones
    recognised = align.recognize(samples, sr)
    try:
        words, phones = align.align_phones(samples, sr, " ".join(w.text for w in recognised))
        found = phone_frames(phones, num_frames, fps)
    except FacegenError:
        words, found = recognised, silence(num_frames)
        warn("no phones could be found in the audio without a transcript: the lips follow the audio alone "
             "(pass --text for better lip sync)")
    if not no_text:
        warn("no transcript given: recognising the words with pocketsphinx (lower quality than with a "
             "transcript; pass --text, --text-file or --alignment for better lips and upper face)")
        return words, "speech recognition", found
    return [], "none (--no-text)", found


def finish_animation(bundle: Bundle, clip: Clip, vertices: np.ndarray | FrameStream) -> Animation:
    """The Animation of a prepared clip with its computed frames (an array or a FrameStream)."""
    return Animation(
        vertices=vertices,
        faces=clip.mesh.faces,
        fps=bundle.features.fps,
        template=clip.mesh.vertices,
        audio=clip.samples,
        sample_rate=clip.sample_rate,
        regions=dict(clip.mesh.regions),
        metadata={
            "source_audio": clip.audio_name,
            "model": bundle.path.name if bundle.path else "in-memory",
            "model_fingerprint": bundle.fingerprint,
            "speaker": bundle.speakers[clip.speaker],
            "words": [{"word": w.text, "start": round(w.start, 4), "end": round(w.end, 4)} for w in clip.words],
            "word_timing": clip.word_timing,
        },
    )


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
    device: str = "auto",
    stream: bool = False,
    progress: Say = silent,
    warn: Say = silent,
    meanwhile: Callable[[], object] | None = None,
) -> Animation:
    """Animate the face for one speech clip.

    Word timings come from `alignment` (a file), else from forced alignment of `text`, else from speech
    recognition; `no_text=True` feeds zero text features instead. `bundle` is a loaded Bundle or a path
    (None: the built-in default model). `device` is "auto" (a CUDA GPU when torch sees one, else the
    CPU), "cpu" or "cuda" (a FacegenError without a GPU).
    With `stream=True` the Animation's vertices are a FrameStream, computed block by block as a writer
    reads them (bounded memory for long clips); otherwise a [T, V, 3] float32 array.
    `progress` receives stage messages for long clips (>= 20 s), `warn` receives notes the user should
    always see.
    In a process that has not imported torch yet (a new `facegen animate`, a script's first call), the forced
    alignment of `text` runs in a forked process while this one imports torch and loads the model
    (align_ahead.py): the same result, sooner. If it still runs once the model is loaded, `meanwhile` is called
    (the CLI imports the writer's libraries).
    """
    PROFILE.mark("animate_start")
    ahead = _start_ahead(audio, text, alignment, no_text, bundle)
    try:
        dev = select_device(device)  # an unusable explicit device fails before any work
        if not isinstance(bundle, Bundle):
            with PROFILE.stage("model_load"):
                bundle = load_bundle(bundle)
        clip = prepare_clip(audio, bundle=bundle, text=text, alignment=alignment, no_text=no_text,
                            speaker=speaker, template=template, text_model=text_model, progress=progress,
                            warn=warn, ahead=ahead, meanwhile=meanwhile)
    finally:
        if ahead is not None:
            ahead.close()
    with PROFILE.stage("inference"):
        frames = predict_frames(bundle, clip.mel, clip.text_features, clip.speaker,
                                template=clip.mesh.vertices, device=dev, phones=clip.phones)
        vertices = frames if stream else np.asarray(frames)
    PROFILE.mark("animate_end")
    return finish_animation(bundle, clip, vertices)


def _start_ahead(audio, text: str | None, alignment, no_text: bool, bundle) -> AlignAhead | None:
    """The forced alignment of `text` started in a process of its own while this one imports torch and loads
    the model (align_ahead.py), when this clip will be force-aligned; else None."""
    if not force_aligned(text, alignment, no_text) or not Path(audio).is_file():
        return None
    if isinstance(bundle, Bundle):  # loaded already, so torch is too: nothing to overlap
        return None
    needs = forced_alignment_of(bundle)
    if needs is None:
        return None
    from facegen import align_ahead

    return align_ahead.start(audio, text, with_phones=needs == "phones")


def force_aligned(text: str | None, alignment, no_text: bool) -> bool:
    """Whether a clip's words come from forced alignment of `text` (not an alignment file, not recognition)."""
    return text is not None and bool(text.strip()) and alignment is None and not no_text


def forced_alignment_of(model: str | os.PathLike | None) -> str | None:
    """What the model bundle at `model` (None: the built-in one) needs from a transcript's forced alignment:
    "phones" (words and phones), "words", or None (an audio-only model, or a header that cannot be read:
    load_bundle will say what is wrong). Read from the header only, without torch."""
    from facegen.bundle import default_bundle_path, read_metadata
    from facegen.model_config import ModelConfig

    try:
        config = ModelConfig.from_dict(read_metadata(model if model is not None else default_bundle_path())
                                       ["model_config"])
    except (FacegenError, KeyError, TypeError, ValueError):
        return None
    return "phones" if config.n_phones else "words" if config.uses_text else None
