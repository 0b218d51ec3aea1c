"""The image detector's network: a compact CenterNet-style single-target detector.

A small strided CNN (strides 2..32) with a top-down feature pyramid back to
stride 4 feeds one head that predicts, on a 56×56 grid for a 224 px image:

- a heatmap per target kind (sigmoid; peak = the target face's centre),
- the sub-cell offset of the centre (so centre precision is not limited by the stride),
- the log distances from the centre to the four bbox edges (left, top, right, bottom).

The centre is predicted directly, not as the middle of the box: under perspective
the projected face centre, which the controller centres, is not the box's middle.
Inference folds batch norm into the convolutions (`fuse_for_inference`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import torch
import torch.nn.functional as F
from torch import nn

from drone_inspect_core.vocabulary import shipped_vocabulary

STRIDE = 4
EDGE_SCALE_PX = 16.0  # edge distances are predicted as log(distance / EDGE_SCALE_PX)


@dataclass(frozen=True)
class DetectorConfig:
    """Architecture and decoding settings, saved as the checkpoint's config.json."""

    input_size: int = 224
    widths: tuple[int, int, int, int, int] = (16, 24, 48, 64, 96)  # channels at strides 2, 4, 8, 16, 32
    neck_width: int = 32
    kinds: tuple[str, ...] = field(default_factory=lambda: shipped_vocabulary().kind_names)
    """The kinds the head has a heatmap for, in order (the shipped vocabulary's, or a fine-tune's)."""
    score_threshold: float = 0.5

    def __post_init__(self) -> None:
        if self.input_size % 32 != 0 or self.input_size < 64:
            raise ValueError(f"input_size must be a multiple of 32 and >= 64, got {self.input_size}")
        if len(self.widths) != 5 or min(self.widths) < 4:
            raise ValueError(f"widths must be 5 channel counts >= 4, got {self.widths}")
        if self.neck_width < 4:
            raise ValueError(f"neck_width must be >= 4, got {self.neck_width}")
        if not self.kinds or len(set(self.kinds)) != len(self.kinds):
            raise ValueError(f"kinds must be distinct and non-empty, got {self.kinds}")
        if not 0.0 < self.score_threshold < 1.0:
            raise ValueError(f"score_threshold must be in (0, 1), got {self.score_threshold}")

    @property
    def grid_size(self) -> int:
        return self.input_size // STRIDE

    @property
    def num_outputs(self) -> int:
        return len(self.kinds) + 2 + 4

    def to_json_dict(self) -> dict[str, object]:
        data = asdict(self)
        data["widths"] = list(self.widths)
        data["kinds"] = list(self.kinds)
        return data

    @classmethod
    def from_json_dict(cls, data: dict[str, object]) -> DetectorConfig:
        """Build from config.json contents; unknown or mistyped fields raise ValueError naming them."""
        known = {f for f in cls.__dataclass_fields__}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown field(s) {sorted(unknown)}")
        kwargs: dict[str, object] = dict(data)
        for name in ("widths", "kinds"):
            if name in kwargs:
                if not isinstance(kwargs[name], list):
                    raise ValueError(f"field {name!r} must be a list")
                kwargs[name] = tuple(kwargs[name])  # type: ignore[arg-type]
        for name, kind in (("input_size", int), ("neck_width", int), ("score_threshold", float)):
            if name in kwargs and not isinstance(kwargs[name], (kind, int)):
                raise ValueError(f"field {name!r} must be a number")
        return cls(**kwargs)  # type: ignore[arg-type]


def conv_bn(c_in: int, c_out: int, stride: int = 1, kernel: int = 3) -> nn.Sequential:
    """Conv (no bias) → BatchNorm → ReLU."""
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, kernel, stride, kernel // 2, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


class CentreNet(nn.Module):
    """(B, 3, S, S) normalised images → (B, K + 6, S/4, S/4) raw head outputs."""

    def __init__(self, config: DetectorConfig) -> None:
        super().__init__()
        self.config = config
        w2, w4, w8, w16, w32 = config.widths
        n = config.neck_width
        self.stem = conv_bn(3, w2, stride=2)  # /2
        self.down4 = conv_bn(w2, w4, stride=2)  # /4
        self.down8 = nn.Sequential(conv_bn(w4, w8, stride=2), conv_bn(w8, w8))  # /8
        self.down16 = nn.Sequential(conv_bn(w8, w16, stride=2), conv_bn(w16, w16))  # /16
        self.down32 = nn.Sequential(conv_bn(w16, w32, stride=2), conv_bn(w32, w32))  # /32
        self.lateral = nn.ModuleList([conv_bn(c, n, kernel=1) for c in (w4, w8, w16, w32)])
        self.smooth = nn.ModuleList([conv_bn(n, n) for _ in range(3)])  # after merging at /16, /8, /4
        self.head = nn.Conv2d(n, config.num_outputs, 1)
        nn.init.constant_(self.head.bias[: len(config.kinds)], -4.0)  # start with a low heatmap (focal loss)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        c4 = self.down4(self.stem(x))  # (B, w4, S/4, S/4)
        c8 = self.down8(c4)
        c16 = self.down16(c8)
        c32 = self.down32(c16)  # (B, w32, S/32, S/32)
        p = self.lateral[3](c32)
        for level, feature in zip((2, 1, 0), (c16, c8, c4), strict=True):
            p = F.interpolate(p, size=feature.shape[-2:], mode="nearest") + self.lateral[level](feature)
            p = self.smooth[2 - level](p)
        return self.head(p)  # (B, K + 6, S/4, S/4)


def fuse_for_inference(model: CentreNet) -> CentreNet:
    """Fold every BatchNorm into the conv before it (eval mode; same outputs, fewer ops)."""
    model.eval()
    for module in model.modules():
        if isinstance(module, nn.Sequential) and len(module) == 3 and isinstance(module[1], nn.BatchNorm2d):
            conv, bn = module[0], module[1]
            fused = torch.nn.utils.fusion.fuse_conv_bn_eval(conv, bn)
            module[0] = fused
            module[1] = nn.Identity()
    return model


def grow_kinds(model: CentreNet, kinds: tuple[str, ...]) -> CentreNet:
    """`model` with a heatmap channel more for each of `kinds` it lacks (appended after its own), every
    other weight kept: the kinds it knows keep working while a fine-tune teaches it the new ones.

    A new channel starts as the mean of the known kinds' channels (a "some target here" prior, which
    the fine-tune then narrows to the new face) with their mean bias (their low resting score).
    """
    new = tuple(k for k in dict.fromkeys(kinds) if k not in model.config.kinds)
    if not new:
        return model
    old_k = len(model.config.kinds)
    grown = CentreNet(replace(model.config, kinds=(*model.config.kinds, *new)))
    state = {k: v for k, v in model.state_dict().items() if not k.startswith("head.")}
    grown.load_state_dict(state, strict=False)
    w, b = model.head.weight.detach(), model.head.bias.detach()  # (K + 6, n, 1, 1), (K + 6,)
    heat_w = w[:old_k].mean(dim=0, keepdim=True).expand(len(new), -1, -1, -1)
    heat_b = b[:old_k].mean().expand(len(new))
    with torch.no_grad():
        grown.head.weight.copy_(torch.cat([w[:old_k], heat_w, w[old_k:]]))
        grown.head.bias.copy_(torch.cat([b[:old_k], heat_b, b[old_k:]]))
    return grown.train(model.training)
