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
from dataclasses import dataclass, field, replace
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


@dataclass
class Bundle:
    model: FaceModel
    features: FeatureConfig
    mel_filters: np.ndarray
    text_backend: str  # id for facegen.text.load_text_backend, or "none"
    speakers: list[str]
    template: Mesh
    provenance: dict = field(default_factory=dict)
    path: Path | None = None

    @property
    def config(self) -> ModelConfig:
        return self.model.cfg

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


def _decompress(tensors: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    out = {}
    for k, v in tensors.items():
        if k.endswith(".__scale__"):
            continue
        scale = tensors.get(f"{k}.__scale__")
        if scale is not None:
            out[k] = v.float() * scale[:, None]
        else:
            out[k] = v.float() if v.is_floating_point() else v
    return out


def save_bundle(bundle: Bundle, path: str | os.PathLike, precision: str = "fp32") -> None:
    """Write the bundle atomically with weights in `precision` (fp32, fp16 or int8, see above)."""
    import torch
    from safetensors.torch import save_file

    from facegen.atomic import atomic_path

    if precision not in PRECISIONS:
        raise FacegenError(f"unknown precision {precision!r}: use one of {', '.join(PRECISIONS)}")
    if bundle.model.cfg.output_basis:  # stored as the paper's plain FC 3V (facegen.model: folded)
        bundle = replace(bundle, model=bundle.model.folded())
    tensors: dict[str, torch.Tensor] = {}
    for k, v in bundle.model.state_dict().items():
        tensors.update(_compress(f"model.{k}", v.detach().cpu().contiguous(), precision))
    tensors["template.vertices"] = torch.from_numpy(np.ascontiguousarray(bundle.template.vertices,
                                                                         np.float32))
    tensors["template.faces"] = torch.from_numpy(np.ascontiguousarray(bundle.template.faces, np.int32))
    for name, idx in bundle.template.regions.items():
        tensors[f"region.{name}"] = torch.from_numpy(np.ascontiguousarray(idx, np.int64))
    tensors["audio.mel_filters"] = torch.from_numpy(np.ascontiguousarray(bundle.mel_filters, np.float32))
    with atomic_path(path) as tmp:
        save_file(tensors, str(tmp), metadata={"facegen": json.dumps(bundle.with_precision_note(precision))})


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
    """Load a bundle (the built-in default model when `path` is None)."""
    import torch
    from safetensors.torch import load_file

    from facegen.model import FaceModel, ModelConfig

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
        with torch.device("meta"):  # no storage, no random init: the weights are assigned below (0.1 s less)
            model = FaceModel(cfg)
        state = {k[len("model."):]: v for k, v in _decompress(tensors).items() if k.startswith("model.")}
        # a sum is NaN/inf when any weight is (20x cheaper than isfinite().all() on the start-up path)
        broken = sorted(k for k, v in state.items()
                        if v.is_floating_point() and not torch.isfinite(torch.sum(v, dtype=torch.float64)))
        if broken:
            raise FacegenError(f"model bundle {path} has NaN or infinite weights ({', '.join(broken[:3])}"
                               f"{' ...' if len(broken) > 3 else ''}): re-train it (a lower learning rate) "
                               "or re-export it")
        model.load_state_dict(state, assign=True)
        regions = {k[len("region."):]: v.numpy() for k, v in tensors.items() if k.startswith("region.")}
        template = Mesh(tensors["template.vertices"].numpy(), tensors["template.faces"].numpy(), regions)
        features = FeatureConfig.from_dict(meta["feature_config"])
        try:
            features.hop_length  # noqa: B018 (refuses an fps that does not divide the sample rate)
        except FacegenError as exc:
            raise FacegenError(f"model bundle {path} is unusable ({exc}): re-train or re-export it") from None
        bundle = Bundle(
            model=model.eval(),
            features=features,
            mel_filters=tensors["audio.mel_filters"].numpy(),
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


__all__ = ["Bundle", "default_bundle_path", "load_bundle", "read_metadata", "save_bundle"]
