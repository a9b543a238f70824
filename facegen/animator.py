"""The Animator: one object owns a run of the network — the model bundle, its text backend, the device and how
a clip's words are timed — and is the one way facegen runs the network (as demucs's `Separator` or whisper's
model + `transcribe`). `facegen.animate`, `facegen animate`, batches, `facegen evaluate` and the analysis
plots all go through it:

    animator = Animator()                              # the built-in model, loaded when first needed
    clip = animator.prepare("line.wav", text="...")    # audio, word timings, features: a Clip
    [animation] = animator.run([clip])                 # the network (packed over many clips)
    animation = animator.animate("line.wav", text="...")   # both in one call

Alignment started ahead: before the model is loaded (a new `facegen animate`, a script's first call), the
forced alignment of the transcript runs in a forked process while this one loads the model and computes the
clip's features (align_ahead.py): the same words, sooner. `animate` does this by itself; a caller with work of
its own to do first (the CLI checks the template's rig) calls `align_ahead` early and `animate` later.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from facegen.align_ahead import AlignAhead, Aligned
from facegen.animation import Animation, check_fps
from facegen.audio import check_speech, is_silent, load_audio, mel_features, num_frames
from facegen.blinks import DEFAULT_RATE, check_blink_rate, check_seed
from facegen.errors import FacegenError
from facegen.expression import Emotion, parse_emotion
from facegen.face.mesh import Mesh, check_topology, read_mesh
from facegen.runtime import PROFILE, SILENT, Reporter, inference_device, silent
from facegen.transcript_match import Match
from facegen.word_timing import NONE, Timing, clip_words, clip_words_and_phones, force_aligned

LONG_INPUT_SECONDS = 20.0  # stage-by-stage progress is reported for clips at least this long
BATCH_SIZE = 16  # clips whose decoder BiLSTMs run as one packed batch


@dataclass
class NetworkInput:
    """What the network reads for one clip: mel [T, n_mels], text features [T, text_dim] or None (zeros),
    the speaker index, and phones [T, P] one-hot (models with a phone stream; None: silence)."""

    mel: np.ndarray
    text_features: np.ndarray | None  # or a facegen.text.WordFrames (the same numbers, made when read)
    speaker: int
    phones: np.ndarray | None = None

    @property
    def num_frames(self) -> int:
        return int(self.mel.shape[0])


@dataclass
class Clip(NetworkInput):
    """A prepared clip: the network's inputs and what its Animation needs besides the frames."""

    audio_name: str = ""
    samples: np.ndarray | None = None
    sample_rate: int = 0
    words: list | None = None
    word_timing: str = NONE
    mesh: Mesh | None = None
    fps: float | None = None  # the Animation's frame rate (None: the network's)
    idle: bool = False  # silent audio: the neutral face in every frame, without the network
    directions: tuple[str, ...] = ()  # the transcript's stage directions ("(laughs)", "[beep]"): not aligned
    match: Match | None = None  # how well the transcript matches the speech (forced alignment only)
    confidences: list[float] | None = None  # of each recognised word (recognition only)
    blink_rate: float = DEFAULT_RATE  # blinks per minute (0: none; facegen.blinks)
    seed: int = 0  # of the random layers (blinks)
    blinks: list | None = None  # the blinks made for it (facegen.blinks.Blink), once run
    saccades: list | None = None  # its gaze (facegen.gaze.Saccade), once run
    head_motion: float = 1.0  # how much the head moves (facegen.head; 0: still)
    head: np.ndarray | None = None  # [T, 3] degrees, once run
    head_pivot: np.ndarray | None = None
    parts: object = None  # facegen.face.parts.PartDrivers, once run
    emotion: Emotion | None = None  # over the whole clip (facegen.expression)
    emotion_spans: list | None = None  # (Emotion, start s, end s) marked in the transcript
    strength: dict | None = None  # the network's motion scaled by region (facegen.strength), None: as it is
    strength_scales: np.ndarray | None = None  # [V], per vertex
    language: str = "en"  # of the transcript (facegen.languages)
    phone_times: list | None = None  # the aligned phones, (CMU phone, start s, end s) (facegen.lip_seal)
    lip_seal: bool = True  # shut the lips on p, b and m (facegen.lip_seal)
    sealed: int = 0  # frames whose lips facegen.lip_seal shut, once run


class Animator:
    """A run of the network: `model` (a loaded Bundle, a bundle path, or None for the built-in model, loaded
    when first needed), `text_model` (where the bundle's text model is, if not where it says), `device`
    ("auto": a CUDA GPU when torch sees one, else the CPU; "cpu"; "cuda": a FacegenError without a GPU)."""

    def __init__(self, model=None, *, text_model: str | None = None, device: str = "auto") -> None:
        from facegen.bundle import Bundle  # torch-free: bundle.py imports torch inside its loaders

        self._bundle = model if isinstance(model, Bundle) else None
        self._model_path = None if self._bundle is not None else model
        self.text_model = text_model
        self._device_name = device
        self._device = None
        self._backend = None
        self._ahead: tuple[tuple, AlignAhead] | None = None

    # ---------------------------------------------------------------------------------------- the run's parts

    @property
    def device(self):
        """Where the network runs: "cpu" (numpy, torch not imported) or a CUDA torch.device (chosen on first
        use: facegen.runtime.inference_device)."""
        if self._device is None:
            self._device = inference_device(self._device_name)
        return self._device

    @property
    def bundle(self):
        """The model bundle (loaded on first use)."""
        if self._bundle is None:
            from facegen.bundle import load_bundle

            with PROFILE.stage("model_load"):
                self._bundle = load_bundle(self._model_path)
        return self._bundle

    def text_backend(self):
        """The bundle's text model (loaded once), checked against the bundle."""
        if self._backend is None:
            from facegen.text import check_text_dim, load_text_backend

            bundle = self.bundle
            with PROFILE.stage("text_model_load"):
                backend = load_text_backend(bundle.text_backend, self.text_model)
            check_text_dim(backend, bundle.config.text_dim, bundle.text_backend)
            self._backend = backend
        return self._backend

    def mesh(self, template: str | os.PathLike | Mesh | None = None) -> Mesh:
        """The face to animate: the bundle's template, or a user mesh of the same topology (refused
        otherwise)."""
        base = self.bundle.template
        if template is None:
            return base
        mesh = template if isinstance(template, Mesh) else read_mesh(template)
        check_topology(mesh, base.num_vertices, base.faces, f"template {template}")
        return Mesh(mesh.vertices, base.faces, base.regions)

    def word_alignment(self) -> str | None:
        """What the model needs from a transcript's forced alignment: "phones", "words" or None (see
        `bundle.forced_alignment_of`); from the loaded bundle, else from its file's header without torch."""
        if self._bundle is not None:
            cfg = self._bundle.config
            return "phones" if cfg.n_phones else "words" if cfg.uses_text else None
        from facegen.bundle import forced_alignment_of

        return forced_alignment_of(self._model_path)

    # --------------------------------------------------------------------------------- alignment ahead

    def align_ahead(self, audio, *, text: str | None, alignment=None, no_text: bool = False,
                    language: str = "en") -> None:
        """Start the forced alignment of `text` to the audio file `audio` in a process of its own, when the
        clip will be force-aligned and the model is not loaded yet (where forking is safe: align_ahead.py);
        `prepare` of the same clip takes its answer. Does nothing where that gains nothing."""
        if self._ahead is not None or self._bundle is not None:
            return
        if not force_aligned(text, alignment, no_text) or not Path(audio).is_file():
            return
        needs = self.word_alignment()
        if needs is None:
            return
        from facegen import align_ahead

        started = align_ahead.start(audio, text, with_phones=needs == "phones", language=language)
        if started is not None:
            self._ahead = ((str(audio), text, language), started)

    def _take_ahead(self, audio, text: str | None, language: str) -> AlignAhead | None:
        if self._ahead is None or self._ahead[0] != (str(audio), text, language):
            return None
        return self._ahead[1]

    def close(self) -> None:
        """Stop an alignment started ahead that no clip took (nothing else holds resources)."""
        if self._ahead is not None:
            self._ahead[1].close()
            self._ahead = None

    # ---------------------------------------------------------------------------------------- clips

    def prepare(self, audio: str | os.PathLike, *, text: str | None = None,
                alignment: str | os.PathLike | None = None, no_text: bool = False,
                speaker: str | int | None = None, template: str | os.PathLike | Mesh | None = None,
                fps: float | None = None, reporter: Reporter = SILENT, aligned: Aligned | None = None,
                meanwhile: Callable[[], object] | None = None, on_mismatch: str = "error",
                blink_rate: float = DEFAULT_RATE, seed: int = 0,
                emotion: str | Emotion | None = None, head_motion: float = 1.0,
                strength=None, language: str | None = None, lip_seal: bool = True) -> Clip:
        """Everything before the network (see `animate`): audio, word timings, text and audio features.
        `aligned`: the forced alignment of `text` done already (a batch's main process aligns waiting items).
        While an alignment started ahead still runs, the transcript's word vectors are computed (they need the
        words, not their times) and `meanwhile` is called (e.g. to import the writer's libraries)."""
        from facegen.head import check_amount

        blink_rate, seed, emotion = check_blink_rate(blink_rate), check_seed(seed), parse_emotion(emotion)
        head_motion = check_amount(head_motion)
        from facegen.strength import parse_strength

        strength = parse_strength(strength)
        from facegen.languages import check_language, check_script

        language = check_language(language).code
        if text:
            check_script(text, check_language(language))
        from facegen.expression import emotion_spans, is_markup, span_times

        spans = emotion_spans(text)  # bad markup: before any work
        ahead = self._take_ahead(audio, text, language) or aligned
        try:
            clip = self._prepare(audio, text=text, alignment=alignment, no_text=no_text, speaker=speaker,
                                 template=template, reporter=reporter, ahead=ahead, meanwhile=meanwhile,
                                 on_mismatch=on_mismatch, language=language)
            clip.fps = check_fps(fps)
            clip.blink_rate, clip.seed, clip.emotion = blink_rate, seed, emotion
            clip.head_motion, clip.strength, clip.lip_seal = head_motion, strength, bool(lip_seal)
            if strength is not None:  # a face without the regions it scales: refused before the network
                from facegen.strength import region_scales

                clip.strength_scales = region_scales(clip.mesh, strength)
            if text:
                from facegen.words import split_directions

                clip.directions = tuple(d for d in split_directions(text)[1] if not is_markup(d))
                clip.emotion_spans = span_times(text, spans, clip.words)
            return clip
        finally:
            if ahead is not None and ahead is not aligned:
                self.close()

    def _prepare(self, audio, *, text, alignment, no_text, speaker, template, reporter: Reporter, ahead,
                 meanwhile, on_mismatch, language) -> Clip:
        bundle = self.bundle
        spk = bundle.speaker_index(speaker)
        mesh = self.mesh(template)
        with PROFILE.stage("audio"):
            samples, sr = load_audio(audio)
        cfg = bundle.features
        check_speech(samples, sr, cfg.fps, name=f"audio file {audio}", silence_ok=True)
        T = num_frames(len(samples) / sr, cfg.fps)
        if is_silent(samples):  # a character listening: the neutral face, no network, no words
            from facegen.words import normalize_transcript

            if (text and normalize_transcript(text)) or alignment is not None:  # "(silence)" is no word
                raise FacegenError(f"audio file {audio} is silent (peak below -80 dBFS) but words were "
                                   "given: pass the recording with the speech, or no words for an idle clip",
                                   param=("text", "alignment"))
            reporter.note(f"audio file {audio} is silent: an idle clip of the neutral face")
            return Clip(np.zeros((T, cfg.n_mels), np.float32), None, spk, audio_name=Path(audio).name,
                        samples=samples, sample_rate=sr, words=[], word_timing=NONE, mesh=mesh, idle=True)
        if len(samples) / sr < LONG_INPUT_SECONDS:
            reporter = replace(reporter, progress=silent)
        with PROFILE.stage("audio_features"):  # before the words: done while an alignment started ahead runs
            mel = mel_features(samples, sr, cfg, bundle.mel_filters)

        timing = Timing([], NONE)
        text_feats = None
        uses_text = bundle.config.uses_text and not no_text
        early: tuple[list[str], np.ndarray] | None = None  # the transcript's words and their vectors
        if ahead is not None and not ahead.ready():  # work that needs no word times, while they are found
            if meanwhile is not None:
                with PROFILE.stage("while_aligning"):
                    meanwhile()
            if uses_text:
                from facegen.text import language_word_vectors
                from facegen.words import spoken_words

                backend = self.text_backend()
                with PROFILE.stage("text_features"):
                    names = [word for word, _ in spoken_words(text, language)]
                    early = names, language_word_vectors(backend, names, language)
        if bundle.config.n_phones:
            with PROFILE.stage("alignment"):
                timing = clip_words_and_phones(samples, sr, T, cfg.fps, text=text, alignment=alignment,
                                               no_text=no_text, reporter=reporter, ahead=ahead,
                                               on_mismatch=on_mismatch, language=language)
        if uses_text:
            if not bundle.config.n_phones:
                with PROFILE.stage("alignment"):
                    timing = clip_words(samples, sr, text=text, alignment=alignment, reporter=reporter,
                                        ahead=ahead, on_mismatch=on_mismatch, language=language)
            from facegen.text import text_features, word_frames

            words = timing.driving  # recognised words the recogniser is unsure of leave the face neutral
            reporter.progress(f"text features ({bundle.text_backend}) for {len(words)} words")
            if early is not None and early[0] == [w.text for w in words]:
                text_feats = word_frames(words, early[1], T, cfg)  # made as the network reads them
            else:
                backend = self.text_backend()
                with PROFILE.stage("text_features"):
                    text_feats = text_features(words, backend, T, cfg, language, lazy=True)

        reporter.progress(f"inference for {T} frames")
        return Clip(mel, text_feats, spk, timing.phones, audio_name=Path(audio).name, samples=samples,
                    sample_rate=sr, words=timing.words, word_timing=timing.source, mesh=mesh,
                    match=timing.match, confidences=timing.confidences, language=language,
                    phone_times=timing.phone_times)

    # ---------------------------------------------------------------------------------------- the network

    def states(self, inputs: Sequence[NetworkInput]) -> list:
        """The decoder states of each input ([T_i, H] tensors): encoders per clip, the decoder BiLSTMs over
        one packed batch (each clip sees exactly its own frames, as alone)."""
        from facegen.inference import batch_decoder_states

        return batch_decoder_states(self.bundle, [(c.mel, c.text_features, c.speaker, c.phones)
                                                  for c in inputs],
                                    device=self.device)

    def frames(self, inputs: Sequence[NetworkInput], templates: Sequence[np.ndarray | None]) -> list:
        """Each input's frames, template + offsets (offsets alone where its template is None), as
        FrameStreams: the decoder states computed now, the output layer as a writer reads the frames
        (inference.py)."""
        from facegen.inference import frame_stream

        return [frame_stream(self.bundle, st, t, speaker=c.speaker)
                for st, t, c in zip(self.states(inputs), templates, inputs, strict=True)]

    def offsets(self, item: NetworkInput) -> np.ndarray:
        """The vertex offsets [T, V, 3] float32 of one input (evaluation against ground truth)."""
        return np.asarray(self.frames([item], [None])[0])

    def encoders(self, item: NetworkInput) -> dict[str, np.ndarray]:
        """The encoders' outputs of one input ("audio" Ha [T, 128] and/or "text" Hl [T, 64]) as float32 arrays
        (the correlation analysis of plots.py)."""
        import torch

        model, dev = self.bundle.model, self.device
        with torch.inference_mode():
            mel = torch.from_numpy(item.mel)[None].to(dev)
            text = (None if item.text_features is None
                    else torch.from_numpy(np.asarray(item.text_features, np.float32))[None].to(dev))
            phones = None if item.phones is None else torch.from_numpy(item.phones)[None].to(dev)
            enc = model.encode(mel, text, model.speaker_one_hot(item.speaker).to(dev), phones)
            return {k: v[0].float().cpu().numpy() for k, v in enc.items()}

    def run(self, clips: Sequence[Clip], *, batch_size: int = BATCH_SIZE) -> list[Animation]:
        """The Animations of prepared clips, in order; the decoder BiLSTMs run `batch_size` clips at a time,
        sorted by length (each clip's result equals its own single run); the frames are FrameStreams."""
        from facegen.inference import FrameStream, frame_stream, states_at_rate

        out: list[Animation | None] = [None] * len(clips)
        fps = self.bundle.features.fps

        def output_frames(clip: Clip) -> int:
            return num_frames(len(clip.samples) / clip.sample_rate, clip.fps or fps)

        for i, clip in enumerate(clips):
            if clip.idle:  # the template in every frame: a stream of no states and no weights
                vertices = clip.mesh.vertices
                out[i] = self.animation(clip, self.layered(clip, FrameStream(
                    np.zeros((output_frames(clip), 1), np.float32), np.zeros((vertices.size, 1), np.float32),
                    vertices)))
        order = sorted((i for i, c in enumerate(clips) if not c.idle), key=lambda i: clips[i].num_frames)
        for b in range(0, len(order), batch_size):
            ids = order[b:b + batch_size]
            for i, states in zip(ids, self.states([clips[i] for i in ids]), strict=True):
                clip = clips[i]  # at another frame rate: the states resampled (a no-op at the network's)
                states = states_at_rate(states, fps, clip.fps or fps, output_frames(clip))
                stream = frame_stream(self.bundle, states, clip.mesh.vertices, speaker=clip.speaker)
                if clip.strength_scales is not None:
                    stream = stream.with_scale(clip.strength_scales, clip.mesh.vertices)
                out[i] = self.animation(clip, self.layered(clip, stream))
        return out

    def layered(self, clip: Clip, stream):
        """The network's frames of `clip` with what it cannot predict (facegen.layers)."""
        from facegen.layers import add_layers

        return add_layers(clip, stream, clip.fps or self.bundle.features.fps)

    def animation(self, clip: Clip, vertices) -> Animation:
        """The Animation of a prepared clip with its computed frames (an array or a FrameStream)."""
        bundle = self.bundle
        return Animation(
            vertices=vertices,
            faces=clip.mesh.faces,
            fps=clip.fps or bundle.features.fps,
            template=clip.mesh.vertices,
            audio=clip.samples,
            sample_rate=clip.sample_rate,
            regions=dict(clip.mesh.regions),
            head=clip.head,
            head_pivot=clip.head_pivot,
            parts=clip.parts,
            metadata={
                "source_audio": clip.audio_name,
                "model": bundle.path.name if bundle.path else "in-memory",
                "model_fingerprint": bundle.fingerprint,
                "speaker": bundle.speakers[clip.speaker],
                "words": [{"word": w.text, "start": round(w.start, 4), "end": round(w.end, 4),
                           **({"confidence": clip.confidences[i]} if clip.confidences else {})}
                          for i, w in enumerate(clip.words)],
                "word_timing": clip.word_timing,
                **({"language": clip.language} if clip.language != "en" else {}),
                **({"stage_directions": list(clip.directions)} if clip.directions else {}),
                **({"transcript_match": clip.match.as_dict()} if clip.match is not None else {}),
                "blinks": {"rate_per_minute": clip.blink_rate, "seed": clip.seed,
                           "times": [[b.start, b.duration] for b in clip.blinks or []]},
                "saccades": [[s.start, s.duration, s.yaw, s.pitch] for s in clip.saccades or []],
                "lip_seal": {"on": clip.lip_seal, "frames": clip.sealed},
                **({"emotion": clip.emotion.as_dict()} if clip.emotion is not None else {}),
                **({"emotion_spans": [{**e.as_dict(), "start": round(a, 4), "end": round(b, 4)}
                                      for e, a, b in clip.emotion_spans]} if clip.emotion_spans else {}),
                **({"strength": clip.strength} if clip.strength else {}),
                "head_motion": {"amount": clip.head_motion, **({} if clip.head is None else {
                    "rms_deg": [round(float(x), 3) for x in np.sqrt(np.mean(clip.head ** 2, 0))]})},
            },
        )

    # ---------------------------------------------------------------------------------------- one call

    def animate(self, audio: str | os.PathLike, *, text: str | None = None,
                alignment: str | os.PathLike | None = None, no_text: bool = False,
                speaker: str | int | None = None, template: str | os.PathLike | Mesh | None = None,
                fps: float | None = None, stream: bool = False, reporter: Reporter = SILENT,
                meanwhile: Callable[[], object] | None = None, on_mismatch: str = "error",
                blink_rate: float = DEFAULT_RATE, seed: int = 0,
                emotion: str | Emotion | None = None, head_motion: float = 1.0,
                strength=None, language: str | None = None, lip_seal: bool = True) -> Animation:
        """Animate the face for one speech clip (see `facegen.animate`)."""
        PROFILE.mark("animate_start")
        check_fps(fps)
        from facegen.languages import check_language

        language = check_language(language).code
        self.align_ahead(audio, text=text, alignment=alignment, no_text=no_text, language=language)
        try:
            self.device  # noqa: B018 - an unusable explicit device fails before any work
            clip = self.prepare(audio, text=text, alignment=alignment, no_text=no_text, speaker=speaker,
                                template=template, fps=fps, reporter=reporter, meanwhile=meanwhile,
                                on_mismatch=on_mismatch, blink_rate=blink_rate, seed=seed, emotion=emotion,
                                head_motion=head_motion, strength=strength, language=language,
                                lip_seal=lip_seal)
        finally:
            self.close()
        with PROFILE.stage("inference"):
            [anim] = self.run([clip])
            if not stream:
                anim.vertices = np.asarray(anim.vertices)
        PROFILE.mark("animate_end")
        return anim


def animate(audio: str | os.PathLike, *, text: str | None = None, alignment: str | os.PathLike | None = None,
            no_text: bool = False, speaker: str | int | None = None, bundle=None,
            template: str | os.PathLike | Mesh | None = None, text_model: str | None = None,
            device: str = "auto", fps: float | None = None, stream: bool = False, reporter: Reporter = SILENT,
            meanwhile: Callable[[], object] | None = None, on_mismatch: str = "error",
            blink_rate: float = DEFAULT_RATE, seed: int = 0,
            emotion: str | Emotion | None = None, head_motion: float = 1.0,
            strength=None, language: str | None = None, lip_seal: bool = True) -> Animation:
    """Animate the face for one speech clip.

    Word timings come from `alignment` (a file), else from forced alignment of `text`, else from speech
    recognition; `no_text=True` feeds zero text features instead. `bundle` is a loaded Bundle or a path
    (None: the built-in default model). `device` is "auto" (a CUDA GPU when torch sees one, else the
    CPU), "cpu" or "cuda" (a FacegenError without a GPU). `fps`: the Animation's frame rate (None: the
    network's, 25; film 24, games 30 or 60): the network runs at its own rate and its decoder states are
    resampled (inference.states_at_rate), so lips and closures stay as they are.
    With `stream=True` the Animation's vertices are a FrameStream, computed block by block as a writer
    reads them (bounded memory for long clips); otherwise a [T, V, 3] float32 array.
    `reporter` (a facegen.Reporter; default: silent) receives stage messages for long clips (>= 20 s) as
    its `progress` and notes the user should always see (e.g. "no transcript given") as its `note`, e.g.
    `Reporter(progress=print, note=print)`. If the forced alignment started ahead (see Animator) still
    runs once the model is loaded, `meanwhile` is called (e.g. to import the writer's libraries).
    `on_mismatch`: a transcript that does not match the speech is refused ("error", a FacegenError) or
    animated with a note ("warn"); either way the metadata's "transcript_match" holds its score
    (facegen.transcript_match.Match: 1 sure, below 0.5 a mismatch).
    `blink_rate`: blinks per minute (0: none), timed by the speech (facegen.blinks: more at pauses and
    phrase ends, never periodic); `seed`: their random draws (the same inputs and seed: the same frames).
    `emotion`: "LABEL[:INTENSITY]" (facegen.expression.EMOTIONS: happy, sad, angry, surprised, afraid,
    disgusted, neutral; intensity 0-1, default 1) over the whole clip, on top of what the words do.
    `head_motion`: how much the head moves with the prosody (facegen.head: nods, tilts, drift; 0: still,
    1: as people move theirs, up to 3), as `Animation.head` (the vertices stay face-local).
    `strength`: "lips=1.2,jaw=0.8,upper=1.5" or a dict: the network's motion scaled by region
    (facegen.strength; 0-3, 1: as it is; the blinks, gaze, emotion and head keep their own controls).
    `language`: the transcript's, a code of `facegen languages` (default "en"): its words aligned with their
    pronunciation in that language (facegen.languages).
    `lip_seal`: shut the lips on the aligned p, b and m where the network leaves a gap (facegen.lip_seal;
    False: the network's lips as they are).
    """
    return Animator(bundle, text_model=text_model, device=device).animate(
        audio, text=text, alignment=alignment, no_text=no_text, speaker=speaker, template=template, fps=fps,
        stream=stream, reporter=reporter, meanwhile=meanwhile, on_mismatch=on_mismatch, blink_rate=blink_rate,
        seed=seed, emotion=emotion, head_motion=head_motion, strength=strength, language=language,
        lip_seal=lip_seal)

