"""The learned trim-colour reader: a small network names a detected target's trim colour from a crop.

The rule reader (`perception.attributes`) tests each palette colour as an explanation of a 1–3 px trim
band. It was tuned on the default look, lossless, and loses much where the pixels differ from what it
was tuned on: through a camera's stream (4:2:0 chroma spreads a thin trim's colour over its
neighbours) and on walls and light no tuning saw. The learned reader is trained on crops around the
truth boxes of collected scenes (`perception.training.colour`, `dronectl train-colour`), each image
also as a stream sends it and every box jittered as much as the detector's are, and so learns what a
trim looks like as the loop receives it.

A crop (`target_crop`) is taken around the box the rule reader reads a trim around
(`perception.attributes.trim_box`: a switch box's snapped to its door, a round target's cut by the edge
grown to its whole ring): `colour_crop`, that box grown by `ColourNetConfig.grow` about its centre (the
trim, and some wall around it to compare with), resized to `crop_px` square, with a fourth channel
that is 1 inside the frame and 0 past its edge (a target cut by the edge, whose box the detector
predicts past it). The network: four 3×3 convolutions (strides 1, 1, 2, 2), a per-kind scale and shift
of the last features (the trim is a ring on a gauge or a valve, a frame on a switch box), a max over
positions, and a small head over the colours.

`ColourReader` reads every detection of a frame in one batch. A kind its network was not trained on
(a user's own kind, `drone_inspect_core.own_kinds`) is read by the rule reader. Its `doubt` is
1 − p(colour) (the rule reader's is a residual in 8-bit YCbCr); both are lower for a surer read, and
twins, being one kind, are always compared on one scale.

Loading parses JSON and tensors only (`config.json`, `model.safetensors`) and never executes code; a
missing, corrupt or mismatched file is a `ColourCheckpointError` naming it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from safetensors.torch import save
from torch import nn

from drone_inspect_core.files import write_atomic, write_json_atomic
from drone_inspect_core.vocabulary import shipped_vocabulary
from perception.attributes import ColourRead, read_colour, trim_box
from perception.checkpoint_files import load_weights, read_config
from perception.errors import ColourCheckpointError

CHECKPOINT_FORMAT = "drone-inspect/colour/1"
WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
SHIPPED_DIR = Path(__file__).resolve().parent / "assets" / "colour"

Box = tuple[float, float, float, float]
_MAX_SOURCE_PX = 512
"""A crop's source region is at most this many pixels a side (the frame shrunk first where it would be
larger), so a box as large as a frame, or a nonsense one, costs a bounded amount of memory."""
_MAX_BOX_FRAMES = 16
"""A box more than this many frames across is no target in it: not read."""


@dataclass(frozen=True)
class ColourNetConfig:
    """Architecture and crop geometry, saved as the checkpoint's config.json."""

    crop_px: int = 40
    grow: float = 1.4
    """The crop is the box grown by this about its centre."""
    widths: tuple[int, int, int, int] = (32, 32, 64, 64)
    hidden: int = 64
    kinds: tuple[str, ...] = field(default_factory=lambda: shipped_vocabulary().kind_names)
    colours: tuple[str, ...] = field(default_factory=lambda: shipped_vocabulary().colour_names)

    def __post_init__(self) -> None:
        if not 16 <= self.crop_px <= 128:
            raise ValueError(f"crop_px must be in [16, 128], got {self.crop_px}")
        if not 1.0 <= self.grow <= 3.0:
            raise ValueError(f"grow must be in [1, 3], got {self.grow}")
        if len(self.widths) != 4 or min(self.widths) < 4 or self.hidden < 4:
            raise ValueError(
                f"widths must be 4 channel counts >= 4 and hidden >= 4, got {self.widths}, {self.hidden}"
            )
        for name, values in (("kinds", self.kinds), ("colours", self.colours)):
            if not values or len(set(values)) != len(values) or not all(isinstance(v, str) for v in values):
                raise ValueError(f"{name} must be distinct names, non-empty, got {values}")

    def to_json_dict(self) -> dict[str, object]:
        return asdict(self)

    @classmethod
    def from_json_dict(cls, data: dict[str, object]) -> ColourNetConfig:
        known = set(cls.__dataclass_fields__)
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown fields {sorted(unknown)}")
        values = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**values)  # type: ignore[arg-type]


def colour_crop(image: np.ndarray, box: Box, crop_px: int, grow: float) -> np.ndarray:
    """(crop_px, crop_px, 4) float32: RGB in [0, 1] of `box` grown by `grow` about its centre, and a
    channel that is 1 where the crop lies in the image, 0 past its edge (zeros there in RGB)."""
    x0, y0, x1, y1 = box
    side = max(x1 - x0, y1 - y0) * grow
    if side > _MAX_SOURCE_PX:  # a box filling a large frame: shrink the frame first, the crop bounded
        scale = _MAX_SOURCE_PX / side
        size = (max(1, round(image.shape[1] * scale)), max(1, round(image.shape[0] * scale)))
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
        x0, y0, x1, y1 = x0 * scale, y0 * scale, x1 * scale, y1 * scale
    cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
    hw, hh = max(x1 - x0, 1.0) / 2.0 * grow, max(y1 - y0, 1.0) / 2.0 * grow
    height, width = image.shape[:2]
    left, top = int(np.floor(cx - hw)), int(np.floor(cy - hh))
    right, bottom = int(np.ceil(cx + hw)), int(np.ceil(cy + hh))
    out = np.zeros((bottom - top, right - left, 4), np.float32)
    a, b, c, d = max(left, 0), max(top, 0), min(right, width), min(bottom, height)
    if c > a and d > b:
        out[b - top : d - top, a - left : c - left, :3] = image[b:d, a:c] / np.float32(255.0)
        out[b - top : d - top, a - left : c - left, 3] = 1.0
    shrink = out.shape[0] > crop_px or out.shape[1] > crop_px
    return cv2.resize(out, (crop_px, crop_px), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def target_crop(image: np.ndarray, box: Box, kind: str | None, config: ColourNetConfig) -> np.ndarray:
    """The network's input for one target, in training and in flight: `colour_crop` around the box the
    rule reader reads a trim around (`perception.attributes.trim_box`: a switch box's snapped to its
    door, a round target's cut by the edge grown to its whole ring)."""
    return colour_crop(image, trim_box(image, box, kind), config.crop_px, config.grow)


class ColourNet(nn.Module):
    """Crop (B, 4, S, S) and kind index (B,) → colour logits (B, C)."""

    def __init__(self, config: ColourNetConfig) -> None:
        super().__init__()
        self.config = config
        w = config.widths
        self.convs = nn.ModuleList(
            [
                nn.Conv2d(4, w[0], 3, padding=1),
                nn.Conv2d(w[0], w[1], 3, padding=1),
                nn.Conv2d(w[1], w[2], 3, padding=1, stride=2),
                nn.Conv2d(w[2], w[3], 3, padding=1, stride=2),
            ]
        )
        self.kind_film = nn.Embedding(len(config.kinds), 2 * w[3])
        self.head = nn.Sequential(
            nn.Linear(w[3] + len(config.kinds), config.hidden),
            nn.ReLU(),
            nn.Linear(config.hidden, len(config.colours)),
        )

    def forward(self, crops: torch.Tensor, kinds: torch.Tensor) -> torch.Tensor:
        x = crops
        for conv in self.convs:
            x = F.relu(conv(x))
        scale, shift = self.kind_film(kinds).chunk(2, dim=1)
        x = F.relu(x * (1.0 + scale[:, :, None, None]) + shift[:, :, None, None])
        pooled = x.amax(dim=(2, 3))
        return self.head(torch.cat([pooled, F.one_hot(kinds, len(self.config.kinds)).float()], dim=1))


def save_checkpoint(run_dir: Path, model: ColourNet, extra: dict[str, object] | None = None) -> None:
    """Write `model.safetensors` and `config.json` (format tag, network config, `extra`: the training run)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    write_atomic(run_dir / WEIGHTS_FILE, save(state))
    write_json_atomic(
        run_dir / CONFIG_FILE,
        {"format": CHECKPOINT_FORMAT, "colour": model.config.to_json_dict(), **(extra or {})},
    )


def load_model(run_dir: str | Path) -> ColourNet:
    """The trained network of a run folder (eval mode); ColourCheckpointError naming the file on any
    problem."""
    root = Path(run_dir)
    path = root / CONFIG_FILE
    fields = read_config(path, CHECKPOINT_FORMAT, "colour", ColourCheckpointError, "dronectl train-colour")
    try:
        config = ColourNetConfig.from_json_dict(fields)
    except (TypeError, ValueError) as exc:
        raise ColourCheckpointError(path, f"field 'colour': {exc}") from None
    unknown = sorted(set(config.colours) - set(shipped_vocabulary().colour_names))
    if unknown:
        raise ColourCheckpointError(path, f"names colours the vocabulary lacks: {unknown}")
    model = ColourNet(config)
    load_weights(model, root / WEIGHTS_FILE, CONFIG_FILE, ColourCheckpointError)
    return model.eval()


class ColourReader:
    """Reads the trim colour of each detected target of a frame: the learned network for the kinds it
    was trained on, the rule reader (`perception.attributes.read_colour`) for any other kind."""

    def __init__(self, model: ColourNet) -> None:
        self.model = model.eval()
        self.config = model.config
        self._kind_index = {kind: i for i, kind in enumerate(self.config.kinds)}

    @classmethod
    def load(cls, run_dir: str | Path) -> ColourReader:
        return cls(load_model(run_dir))

    @classmethod
    def shipped(cls) -> ColourReader:
        """The weights shipped with the package (see perception/assets/README.md)."""
        return cls.load(SHIPPED_DIR)

    def knows(self, kind: str | None) -> bool:
        """Whether the network reads `kind` (else the rule reader does)."""
        return kind in self._kind_index

    @torch.inference_mode()
    def read_all(
        self, image: np.ndarray, targets: Sequence[tuple[Box, str | None]]
    ) -> list[ColourRead | None]:
        """The trim colour of each (box, kind) in the RGB uint8 `image`, in order; None where a box is
        degenerate (no pixel of it in the frame, or more than `_MAX_BOX_FRAMES` frames across) or the rule
        reader reads nothing."""
        reads: list[ColourRead | None] = [None] * len(targets)
        learned = []
        for i, (box, kind) in enumerate(targets):
            if not self.knows(kind):
                reads[i] = read_colour(image, box, kind)
            elif _in_frame(box, image.shape[1], image.shape[0]):
                learned.append(i)
        if learned:
            crops = np.stack([target_crop(image, *targets[i], self.config) for i in learned])
            kinds = torch.tensor([self._kind_index[targets[i][1]] for i in learned])  # type: ignore[index]
            probs = torch.softmax(self.model(torch.from_numpy(crops).permute(0, 3, 1, 2), kinds), dim=1)
            best = probs.max(dim=1)
            for j, i in enumerate(learned):
                name = self.config.colours[int(best.indices[j])]
                reads[i] = ColourRead(name, 1.0 - float(best.values[j]))
        return reads


def _in_frame(box: Box, width: int, height: int) -> bool:
    x0, y0, x1, y1 = box
    if not all(np.isfinite(v) for v in box):
        return False
    sane = max(x1 - x0, y1 - y0) <= _MAX_BOX_FRAMES * max(width, height)
    return sane and x1 > x0 and y1 > y0 and x1 > 0 and y1 > 0 and x0 < width and y0 < height
