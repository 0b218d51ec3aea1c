"""The latent dynamics planner's model shape (`ModelConfig`): what a checkpoint's `config.json` holds.

The model half of a run's configuration: written to the checkpoint when it is trained and checked
again when it is loaded for flying. How it is trained (losses, augmentation, optimisation, the
presets) is research and lives in `controller.training.config`.

Goal prototype (DESIGN.md): z*(instr) = fuse(mean_i E_img(goal_i), E_inst(instr)). During training
the goal mean is taken every step over a sample of goal images; after training the mean over all
goal images (eval mode) is stored in the checkpoint as `goal_image_embedding`, used at inference.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any, Literal

Distance = Literal["cosine", "euclidean", "both"]
Pooling = Literal["gap", "flatten", "keypoints"]
Fusion = Literal["linear", "gated"]
FUSIONS: tuple[str, ...] = ("linear", "gated")
Conditioning = Literal["none", "film"]
CONDITIONINGS: tuple[str, ...] = ("none", "film")
POOLINGS: tuple[str, ...] = ("gap", "flatten", "keypoints")

DISTANCES: tuple[str, ...] = ("cosine", "euclidean", "both")
SHIFT_INIT_STD = 0.01
"""The spread of the global shifts g_X, g_Z at initialisation as the model has always been built (the
paper does not give one); a training choice (`TrainConfig.shift_init_std`), not a shape."""
GOAL_PROTOTYPE_RULE = "z*(instr) = fuse(mean_i E_img(goal_i), E_inst(instr)); goal mean stored in checkpoint"


@dataclass(frozen=True)
class ModelConfig:
    """Shapes of every component (paper appendix, Table 4) plus the two CPU knobs."""

    image_size: int = 224  # square input, pixels
    base_width: int = 64  # channels of the first residual stage; stages are ×[1, 2, 4, 8]
    coord_channels: bool = False  # add (u, v) planes to the RGB input
    # Head of E_img: "gap" (paper: global average pool + linear), "flatten" (the final S/32 × S/32
    # map flattened + linear: keeps where features are), "keypoints" (spatial softmax: each channel's
    # expected (u, v), concatenated with the pooled features, + linear).
    pooling: Pooling = "gap"
    # fuse: "linear" (paper: W·concat(E_img, E_inst)); "gated" adds (A·E_img) ⊙ (B·E_inst), so the
    # instruction can weight image features (which object to centre when a distractor is in view).
    # With a linear fusion z_s − z* = W_img·(E_img − goal mean) does not depend on the instruction.
    fusion: Fusion = "linear"
    # How the instruction reaches E_img: "none" (paper: only through the fusion) or "film" (FiLM:
    # the instruction embedding scales and shifts every residual stage's channels, so the image
    # features already single out the named target when several targets are in view).
    conditioning: Conditioning = "none"
    # A head on z_s giving the probability that the named target is in view (negative states).
    presence_head: bool = False
    latent_dim: int = 128  # d: width of E_img, E_inst, z_s, Δ, g
    vocab_size: int = 5000  # upper bound; the tokenizer's real size is written here at build time
    max_tokens: int = 50
    text_layers: int = 2
    text_heads: int = 4
    text_ff: int = 256
    text_dropout: float = 0.1
    action_dim: int = 16  # per axis; z_a = concat(E_X, E_Z) is 32 wide
    dynamics_hidden: int = 128
    dynamics_dropout: float = 0.2
    distance: Distance = "cosine"

    def __post_init__(self) -> None:
        if self.image_size < 32:
            raise ValueError(f"image_size must be >= 32, got {self.image_size}")
        if self.base_width < 4 or self.latent_dim < 8:
            raise ValueError("base_width must be >= 4 and latent_dim >= 8")
        if self.latent_dim % self.text_heads:
            raise ValueError(f"latent_dim {self.latent_dim} must divide by text_heads {self.text_heads}")
        if self.distance not in DISTANCES:
            raise ValueError(f"distance must be one of {DISTANCES}, got {self.distance!r}")
        if self.pooling not in POOLINGS:
            raise ValueError(f"pooling must be one of {POOLINGS}, got {self.pooling!r}")
        if self.fusion not in FUSIONS:
            raise ValueError(f"fusion must be one of {FUSIONS}, got {self.fusion!r}")
        if self.conditioning not in CONDITIONINGS:
            raise ValueError(f"conditioning must be one of {CONDITIONINGS}, got {self.conditioning!r}")
        if self.max_tokens < 4:
            raise ValueError(f"max_tokens must be >= 4, got {self.max_tokens}")

    @property
    def in_channels(self) -> int:
        return 5 if self.coord_channels else 3

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ModelConfig:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown model config keys: {unknown}")
        return cls(**data)
