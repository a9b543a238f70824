"""The network's configuration (model.py), without torch: a bundle's header is read with it before torch is
imported (what a model needs from the words: bundle.forced_alignment_of)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

MODALITIES = ("both", "audio", "text")
FUSIONS = ("tensor", "concat")


@dataclass
class ModelConfig:
    num_vertices: int
    num_speakers: int
    text_dim: int = 384
    n_mels: int = 128
    modalities: str = "both"  # both | audio | text
    fusion: str = "tensor"  # tensor | concat (only with both)
    conv_channels: int = 128
    kernel_size: int = 3
    dilations: list[int] = field(default_factory=lambda: [1, 2, 4, 8])
    audio_dim: int = 128
    text_hidden: int = 128
    text_dim_out: int = 64
    decoder_dim: int = 128
    lstm_dim: int = 128
    lstm_layers: int = 2
    leaky_slope: float = 0.2
    output_basis: int = 0  # K > 0: the output FC is trained in a K-dim PCA basis (see the module docstring)
    n_phones: int = 0  # P > 0: a per-frame phone one-hot joins the mel bands at the audio encoder's input

    def __post_init__(self) -> None:
        if self.modalities not in MODALITIES:
            raise ValueError(f"modalities must be one of {MODALITIES}, not {self.modalities!r}")
        if self.fusion not in FUSIONS:
            raise ValueError(f"fusion must be one of {FUSIONS}, not {self.fusion!r}")

    @property
    def uses_audio(self) -> bool:
        return self.modalities in ("both", "audio")

    @property
    def uses_text(self) -> bool:
        return self.modalities in ("both", "text")

    @property
    def receptive_field(self) -> int:
        """Frames of context the audio convolutions see on each side."""
        return sum(d * (self.kernel_size - 1) // 2 for d in self.dilations)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> ModelConfig:
        return cls(**d)
