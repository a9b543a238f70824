"""Model bundle: one .safetensors file with the weights and everything needed to use them.

Tensors: the network's state dict under `model.*`, plus `template.vertices` [V,3] f32,
`template.faces` [F,3] i32, `region.<name>` (vertex indices, i64) and `audio.mel_filters`.
Metadata (the safetensors header, key "facegen", JSON): format version, model and feature config,
text backend id and dimension, speaker names, topology fingerprint, provenance. No pickle anywhere.
Weights may be stored compressed (`save_bundle(..., precision=...)`) and are loaded back as float32:
"fp16" stores every float tensor as float16 (half the size); "int8" also stores each large matrix
(≥ 1M entries: the output layer of 70,110 × 256) as int8 with one float32 scale per row (absmax / 127),
a quarter of the size — the shipped default model uses it to stay well under 40 MB.
"""

from __future__ import annotations

import json
import os
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facegen.audio import FeatureConfig
from facegen.errors import FacegenError
from facegen.face.mesh import Mesh

# torch is imported by what loads or saves weights: `facegen info` reads metadata without it
if TYPE_CHECKING:
    import torch

    from facegen.model import FaceModel, ModelConfig

FORMAT_VERSION = 1
DEFAULT_BUNDLE = "default.safetensors"


class Bundle:
    """A loaded model: the network, its features' configuration, mel filters, text backend id, speakers, the
    template face, provenance.

    The network is held two ways, each made from the other when first asked for: `weights`, its float32
    state dict as numpy arrays with the plain FC 3V output layer (what inference on the CPU reads:
    facegen.numpy_network, no torch), and `model`, the torch FaceModel (training, a CUDA device). A loaded
    bundle has weights and builds the torch model only if asked (importing torch); a bundle made from a
    torch model (training, tests) reads its weights from that model each time, so they follow its changes.
    """

    def __init__(self, model: FaceModel | None = None, *, features: FeatureConfig, mel_filters: np.ndarray,
                 text_backend: str, speakers: list[str], template: Mesh, provenance: dict | None = None,
                 path: Path | None = None, weights: dict[str, np.ndarray] | None = None,
                 config: ModelConfig | None = None) -> None:
        if (model is None) == (weights is None) or (weights is not None and config is None):
            raise ValueError("a Bundle needs a torch model, or weights and their config")
        self._model, self._weights, self._config = model, weights, config
        self.features = features
        self.mel_filters = mel_filters
        self.text_backend = text_backend  # id for facegen.text.load_text_backend, or "none"
        self.speakers = speakers
        self.template = template
        self.provenance = {} if provenance is None else provenance
        self.path = path

    @property
    def model(self) -> FaceModel:
        """The torch network (built from the weights on first use: that imports torch)."""
        if self._model is None:
            import torch

            from facegen.model import FaceModel

            with torch.device("meta"):  # no storage, no random init: the weights are assigned below
                model = FaceModel(self._config)
            model.load_state_dict({k: torch.from_numpy(v) for k, v in self._weights.items()}, assign=True)
            self._model = model.eval()
        return self._model

    @property
    def weights(self) -> dict[str, np.ndarray]:
        """The network's float32 state dict, output layer as the plain FC 3V (FaceModel.folded)."""
        if self._weights is not None:
            return self._weights
        model = self._model.folded()
        return {k: v.detach().cpu().float().numpy() for k, v in model.state_dict().items()}

    @property
    def config(self) -> ModelConfig:
        return self._model.cfg if self._model is not None else self._config

    @property
    def fingerprint(self) -> str:
        return self.template.fingerprint()

    def speaker_index(self, speaker: str | int | None) -> int:
        """Resolve a speaker given by name or 0-based index; None means the first one."""
        if speaker is None:
            return 0
        s = str(speaker)
        if s in self.speakers:
            return self.speakers.index(s)
        if s.isdigit() and len(s) < 10 and int(s) < len(self.speakers):
            return int(s)
        valid = ", ".join(f"{i}={n}" for i, n in enumerate(self.speakers))
        shown = s if len(s) <= 40 else s[:40] + "..."
        raise FacegenError(f"unknown speaker {shown!r}: choose one of {valid} (name or index)",
                           param="speaker")

    def metadata(self) -> dict:
        return {
            "format_version": FORMAT_VERSION,
            "model_config": self.config.to_dict(),
            "feature_config": self.features.to_dict(),
            "text_backend": {"id": self.text_backend, "dim": self.config.text_dim},
            "speakers": self.speakers,
            "topology": {
                "num_vertices": self.template.num_vertices,
                "num_faces": int(self.template.faces.shape[0]),
                "fingerprint": self.fingerprint,
            },
            "regions": {k: len(v) for k, v in self.template.regions.items()},
            "provenance": self.provenance,
        }

    def with_precision_note(self, precision: str) -> dict:
        meta = self.metadata()
        meta["weights_precision"] = precision
        return meta


PRECISIONS = ("fp32", "fp16", "int8")
INT8_MIN_SIZE = 1 << 20


def _compress(name: str, v: torch.Tensor, precision: str) -> dict[str, torch.Tensor]:
    import torch

    if precision == "fp32" or not v.is_floating_point():
        return {name: v}
    if precision == "int8" and v.ndim == 2 and v.numel() >= INT8_MIN_SIZE:
        scale = v.abs().amax(dim=1).clamp(min=1e-12) / 127.0
        q = torch.round(v / scale[:, None]).clamp(-127, 127).to(torch.int8)
        return {name: q.contiguous(), f"{name}.__scale__": scale.float().contiguous()}
    return {name: v.half()}


def _decompress(tensors: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Stored tensors as float32 (int8 matrices times their row scales); integer tensors as they are."""
    out = {}
    for k, v in tensors.items():
        if k.endswith(".__scale__"):
            continue
        scale = tensors.get(f"{k}.__scale__")
        if scale is not None:
            out[k] = v.astype(np.float32) * scale[:, None]
        else:
            out[k] = v.astype(np.float32) if v.dtype.kind == "f" else v
    return out


def save_bundle(bundle: Bundle, path: str | os.PathLike, precision: str = "fp32") -> None:
    """Write the bundle atomically with weights in `precision` (fp32, fp16 or int8, see above)."""
    import torch
    from safetensors.torch import save_file

    from facegen.atomic import atomic_path

    if precision not in PRECISIONS:
        raise FacegenError(f"unknown precision {precision!r}: use one of {', '.join(PRECISIONS)}")
    model = bundle.model.folded()  # stored as the paper's plain FC 3V (facegen.model)
    tensors: dict[str, torch.Tensor] = {}
    for k, v in model.state_dict().items():
        tensors.update(_compress(f"model.{k}", v.detach().cpu().contiguous(), precision))
    tensors["template.vertices"] = torch.from_numpy(np.ascontiguousarray(bundle.template.vertices,
                                                                         np.float32))
    tensors["template.faces"] = torch.from_numpy(np.ascontiguousarray(bundle.template.faces, np.int32))
    for name, idx in bundle.template.regions.items():
        tensors[f"region.{name}"] = torch.from_numpy(np.ascontiguousarray(idx, np.int64))
    tensors["audio.mel_filters"] = torch.from_numpy(np.ascontiguousarray(bundle.mel_filters, np.float32))
    with atomic_path(path) as tmp:
        meta = {**bundle.with_precision_note(precision), "model_config": model.cfg.to_dict()}  # folded
        save_file(tensors, str(tmp), metadata={"facegen": json.dumps(meta)})


def default_bundle_path() -> Path:
    return Path(str(resources.files("facegen") / "models" / DEFAULT_BUNDLE))


def read_metadata(path: str | os.PathLike) -> dict:
    """The bundle's JSON metadata, without loading the weights."""
    from safetensors import safe_open

    path = Path(path)
    if not path.is_file():
        raise FacegenError(f"model bundle {path} does not exist: pass the path of a .safetensors bundle",
                           param="bundle")
    if not _looks_like_safetensors(path):
        raise FacegenError(f"{path} is not a model bundle (not a safetensors file): pass a facegen "
                           ".safetensors bundle", param="bundle")
    try:
        with safe_open(str(path), framework="numpy") as f:
            raw = (f.metadata() or {}).get("facegen")
    except Exception as exc:  # safetensors raises its own error types for corrupt headers
        raise FacegenError(
            f"model bundle {path} is corrupt or truncated ({exc}): re-download or re-train it"
        ) from exc
    if raw is None:
        raise FacegenError(f"{path} is a safetensors file but not a facegen bundle (no 'facegen' metadata)")
    try:
        meta = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise FacegenError(f"model bundle {path} has corrupt metadata ({exc}): re-train or re-export "
                           "it") from exc
    if meta.get("format_version", 0) > FORMAT_VERSION:
        raise FacegenError(
            f"model bundle {path} has format version {meta['format_version']}, newer than this facegen "
            f"reads ({FORMAT_VERSION}): upgrade facegen"
        )
    return meta


def _looks_like_safetensors(path: Path) -> bool:
    """A safetensors file starts with its JSON header's length (8 bytes, little endian) and then "{"."""
    with open(path, "rb") as f:
        head = f.read(9)
    if len(head) < 9:
        return False
    return 2 <= int.from_bytes(head[:8], "little") <= path.stat().st_size - 8 and head[8:9] == b"{"


def read_template(path: str | os.PathLike | None = None) -> Mesh:
    """A bundle's template mesh (the built-in model's when `path` is None), read without torch or the weights
    (validate and render of a .npy need the face, not the network)."""
    from safetensors import safe_open

    path = default_bundle_path() if path is None else Path(path)
    read_metadata(path)  # a missing, foreign or corrupt file: its one-line error
    try:
        with safe_open(str(path), framework="numpy") as f:
            names = [k for k in f.keys() if k.startswith("region.")]  # noqa: SIM118 - safe_open is no dict
            regions = {k.removeprefix("region."): f.get_tensor(k) for k in names}
            return Mesh(f.get_tensor("template.vertices"), f.get_tensor("template.faces"), regions)
    except Exception as exc:
        raise FacegenError(f"model bundle {path} is corrupt or truncated ({exc}): re-download or re-train "
                           "it", param="bundle") from exc


def load_bundle(path: str | os.PathLike | None = None) -> Bundle:
    """Load a bundle (the built-in default model when `path` is None), without torch (`Bundle.model` imports
    it when asked for)."""
    from safetensors.numpy import load_file

    from facegen.model_config import ModelConfig
    from facegen.numpy_network import check_weights

    if path is None:
        path = default_bundle_path()
        if not path.is_file():
            raise FacegenError(
                "the built-in default model is missing from this installation: reinstall facegen "
                "or pass a model bundle", param="bundle"
            )
    path = Path(path)
    meta = read_metadata(path)
    try:
        tensors = load_file(str(path))
    except Exception as exc:
        raise FacegenError(f"model bundle {path} is corrupt or truncated ({exc}): re-download or re-train "
                           "it") from exc
    try:
        cfg = ModelConfig.from_dict(meta["model_config"])
        weights = {k[len("model."):]: v for k, v in _decompress(tensors).items() if k.startswith("model.")}
        # a sum is NaN/inf when any weight is (cheaper than isfinite().all() on the start-up path)
        broken = sorted(k for k, v in weights.items()
                        if v.dtype.kind == "f" and not np.isfinite(np.sum(v, dtype=np.float64)))
        if broken:
            raise FacegenError(f"model bundle {path} has NaN or infinite weights ({', '.join(broken[:3])}"
                               f"{' ...' if len(broken) > 3 else ''}): re-train it (a lower learning rate) "
                               "or re-export it")
        check_weights(weights, cfg)
        regions = {k[len("region."):]: v for k, v in tensors.items() if k.startswith("region.")}
        template = Mesh(tensors["template.vertices"], tensors["template.faces"], regions)
        features = FeatureConfig.from_dict(meta["feature_config"])
        try:
            features.hop_length  # noqa: B018 (refuses an fps that does not divide the sample rate)
        except FacegenError as exc:
            raise FacegenError(f"model bundle {path} is unusable ({exc}): re-train or re-export it") from None
        bundle = Bundle(
            weights=weights,
            config=cfg,
            features=features,
            mel_filters=tensors["audio.mel_filters"],
            text_backend=meta["text_backend"]["id"],
            speakers=list(meta["speakers"]),
            template=template,
            provenance=meta.get("provenance", {}),
            path=path,
        )
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise FacegenError(f"model bundle {path} is incomplete or inconsistent ({exc}): re-train or "
                           "re-export it") from exc
    if bundle.fingerprint != meta["topology"]["fingerprint"]:
        raise FacegenError(f"model bundle {path} has a template that does not match its topology "
                           "fingerprint: re-export it")
    return bundle


def forced_alignment_of(model: str | os.PathLike | None) -> str | None:
    """What the model bundle at `model` (None: the built-in one) needs from a transcript's forced alignment:
    "phones" (words and phones), "words", or None (an audio-only model, or a header that cannot be read:
    load_bundle will say what is wrong). Read from the header only, without torch."""
    from facegen.model_config import ModelConfig

    try:
        config = ModelConfig.from_dict(read_metadata(model if model is not None else default_bundle_path())
                                       ["model_config"])
    except (FacegenError, KeyError, TypeError, ValueError):
        return None
    return "phones" if config.n_phones else "words" if config.uses_text else None


__all__ = ["Bundle", "default_bundle_path", "forced_alignment_of", "load_bundle", "read_metadata",
           "save_bundle"]
