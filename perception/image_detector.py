"""The image-based target detector: pixels in, `Detection | None` out.

Loads a run folder written by `dronectl train-detector` (`model.safetensors` +
`config.json`; loading parses JSON and tensors only and never executes code) or the
weights shipped in `perception/assets/detector/`. A frame of any size is resized to
the network's input size and the result scaled back to the frame's pixels.

`detect` decodes the single strongest heatmap peak over all kinds: its value is the
confidence, its channel the kind, the offset head places the centre inside the
cell and the edge head gives the box. Below `score_threshold` the detector
returns None: an absent target, or one whose centre is out of the image (the
network is trained to stay silent then, so it never reports a confident box
for a target it cannot centre on).

`detect_all` decodes every target: each local maximum of each kind's heatmap
(3×3 max-pool non-maximum suppression) at or above `score_threshold`, strongest
first; a weaker peak whose centre lies inside a stronger detection's box is the
same object seen as another kind (or a second peak of it) and is dropped. Each
detection also carries its attribute, the trim colour read from the pixels, with its doubt: by the
learned colour reader (`perception.colour_model`; a run folder's own in its `colour/` folder, else the
shipped one), which leaves kinds it was not trained on to the rule reader (`perception.attributes`).

The network runs on torch or, exported from the loaded weights when the detector is made, on
ONNX Runtime (`backend`, default "auto": ONNX when onnxruntime is installed); the decoding is the
same for both, and their head outputs agree within 1e-4 (tests/test_perception_onnx.py).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from safetensors.torch import save

from drone_inspect_core.files import write_atomic, write_json_atomic
from drone_inspect_core.onnx_runtime import OnnxModule, onnx_for
from drone_inspect_core.own_kinds import checkpoint_kinds
from perception.attributes import ColourRead, read_colour
from perception.checkpoint_files import load_weights, read_config
from perception.colour_model import SHIPPED_DIR as COLOUR_SHIPPED_DIR
from perception.colour_model import ColourReader
from perception.detector_model import EDGE_SCALE_PX, STRIDE, CentreNet, DetectorConfig, fuse_for_inference
from perception.errors import DetectorCheckpointError
from perception.types import Detection

log = logging.getLogger(__name__)

CHECKPOINT_FORMAT = "drone-inspect/detector/1"
WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
SHIPPED_DIR = Path(__file__).resolve().parent / "assets" / "detector"
COLOUR_DIR = "colour"
"""A run folder's own colour reader, where it has one (`ImageDetector.load`)."""


def normalise(images_uint8: torch.Tensor) -> torch.Tensor:
    """(B, 3, S, S) uint8 → float inputs centred on 0 (the same in training and inference)."""
    return (images_uint8.float() / 255.0 - 0.5) / 0.25


def save_checkpoint(run_dir: Path, model: CentreNet, extra: dict[str, object] | None = None) -> None:
    """Write `model.safetensors` and `config.json` (format tag, detector config, `extra` info: the
    training run, and `kinds`, the words of the kinds it knows beyond the shipped ones)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    write_atomic(run_dir / WEIGHTS_FILE, save(state))  # whole or not at all, as every file here
    payload = {"format": CHECKPOINT_FORMAT, "detector": model.config.to_json_dict(), **(extra or {})}
    write_json_atomic(run_dir / CONFIG_FILE, payload)


def load_config(run_dir: Path) -> DetectorConfig:
    """The detector config of a run folder; DetectorCheckpointError naming the file on any problem."""
    path = run_dir / CONFIG_FILE
    fields = read_config(
        path, CHECKPOINT_FORMAT, "detector", DetectorCheckpointError, "dronectl train-detector"
    )
    try:
        return DetectorConfig.from_json_dict(fields)
    except (TypeError, ValueError) as exc:
        raise DetectorCheckpointError(path, f"field 'detector': {exc}") from None


def load_model(run_dir: str | Path) -> CentreNet:
    """The trained network of a run folder (eval mode, not fused)."""
    root = Path(run_dir)
    model = CentreNet(load_config(root))
    load_weights(model, root / WEIGHTS_FILE, CONFIG_FILE, DetectorCheckpointError)
    return model.eval()


class ImageDetector:
    """Detect the inspection target in RGB images with a trained `CentreNet`.

    `score_threshold` overrides the checkpoint's. The detector takes the model over
    (its batch norms are folded in place). `backend`: "torch", "onnx" (OnnxBackendError without
    onnxruntime) or "auto" (ONNX when onnxruntime is installed and the export checks out; logged).
    `threads` is the ONNX Runtime thread count; on torch, run single frames on one thread
    (`torch.set_num_threads(1)`) for the steadiest latency on a small CPU.
    """

    def __init__(
        self,
        model: CentreNet,
        score_threshold: float | None = None,
        backend: str = "auto",
        threads: int | None = 1,
        colour_reader: ColourReader | None = None,
    ) -> None:
        self.config = model.config
        self.colour_reader = colour_reader
        """Reads `detect_all`'s trim colours (`perception.colour_model`); None: the rule reader alone."""
        self.score_threshold = self.config.score_threshold if score_threshold is None else score_threshold
        if not 0.0 < self.score_threshold < 1.0:
            raise ValueError(f"score_threshold must be in (0, 1), got {self.score_threshold}")
        self._model = fuse_for_inference(model).to(memory_format=torch.channels_last)
        self._onnx = onnx_for(backend, "image detector", lambda: self._export(threads))
        self.backend = "torch" if self._onnx is None else "onnx"
        self.own_kinds: dict[str, dict[str, object]] = {}
        """The words of the kinds it knows beyond the shipped ones (its checkpoint's `kinds`)."""

    @classmethod
    def load(
        cls,
        run_dir: str | Path,
        score_threshold: float | None = None,
        backend: str = "auto",
        threads: int | None = 1,
    ) -> ImageDetector:
        """A run folder's detector, reading colours with the colour reader in its `colour/` folder
        (`dronectl train-colour`), else the shipped one."""
        own_colour = Path(run_dir) / COLOUR_DIR
        colour = ColourReader.load(own_colour if own_colour.is_dir() else COLOUR_SHIPPED_DIR)
        detector = cls(load_model(run_dir), score_threshold, backend, threads, colour)
        detector.own_kinds = checkpoint_kinds(run_dir)
        return detector

    @classmethod
    def shipped(cls, score_threshold: float | None = None, backend: str = "auto") -> ImageDetector:
        """The weights shipped with the package (see perception/assets/README.md)."""
        return cls.load(SHIPPED_DIR, score_threshold, backend)

    def _export(self, threads: int | None) -> OnnxModule:
        """The network as an ONNX Runtime session, checked against torch on random inputs."""
        size = self.config.input_size
        example = torch.randn(2, 3, size, size, generator=torch.Generator().manual_seed(0))
        return OnnxModule.export(self._model, (example,), ("image",), ("heads",), "image detector", threads)

    def _prepare(self, image: np.ndarray) -> np.ndarray:
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"detect needs an RGB uint8 (H, W, 3) image, got {image.dtype} {image.shape}")
        size = self.config.input_size
        if image.shape[:2] != (size, size):
            image = cv2.resize(image, (size, size), interpolation=cv2.INTER_AREA)
        return image

    def detect(self, image: np.ndarray) -> Detection | None:
        """The target in one RGB uint8 (H, W, 3) image, or None."""
        return self.detect_batch([image])[0]

    def detect_all(self, image: np.ndarray) -> list[Detection]:
        """Every target in one RGB uint8 (H, W, 3) image, strongest first, with kind and attribute."""
        return self.detect_all_batch([image])[0]

    @torch.inference_mode()
    def detect_batch(self, images: Sequence[np.ndarray]) -> list[Detection | None]:
        """`detect` for several images at once (evaluation)."""
        if not images:
            return []
        out = self._forward(images)  # (B, K + 6, G, G)
        return [self._decode(out[i], images[i].shape[1], images[i].shape[0]) for i in range(len(images))]

    @torch.inference_mode()
    def detect_all_batch(self, images: Sequence[np.ndarray]) -> list[list[Detection]]:
        """`detect_all` for several images at once."""
        if not images:
            return []
        out = self._forward(images)
        return [self._decode_all(out[i], images[i]) for i in range(len(images))]

    def _forward(self, images: Sequence[np.ndarray]) -> torch.Tensor:
        batch = np.stack([self._prepare(im) for im in images])  # (B, S, S, 3)
        x = normalise(torch.from_numpy(batch).permute(0, 3, 1, 2)).contiguous(
            memory_format=torch.channels_last
        )
        if self._onnx is None:
            return self._model(x)  # (B, K + 6, G, G)
        return torch.from_numpy(self._onnx.run(x.numpy())[0])

    def _decode(self, out: torch.Tensor, width: int, height: int) -> Detection | None:
        k = len(self.config.kinds)
        grid = out.shape[-1]
        heat = out[:k]
        flat = int(torch.argmax(heat))
        kind, cell = divmod(flat, grid * grid)
        j, i = divmod(cell, grid)
        score = float(torch.sigmoid(heat[kind, j, i]))
        if score < self.score_threshold:
            return None
        return self._detection_at(out, kind, j, i, score, width, height)

    def _decode_all(self, out: torch.Tensor, image: np.ndarray) -> list[Detection]:
        height, width = image.shape[:2]
        heat = torch.sigmoid(out[: len(self.config.kinds)])  # (K, G, G)
        peaks = (heat == F.max_pool2d(heat[None], 3, stride=1, padding=1)[0]) & (heat >= self.score_threshold)
        found = sorted(
            ((float(heat[kind, j, i]), kind, j, i) for kind, j, i in peaks.nonzero().tolist()), reverse=True
        )
        kept: list[tuple[Detection, tuple[float, float, float, float]]] = []
        for score, kind, j, i in found:
            det, whole = self._detection_and_box(out, kind, j, i, score, width, height)
            u, v = det.centre_px
            if any(o.bbox_px[0] <= u <= o.bbox_px[2] and o.bbox_px[1] <= v <= o.bbox_px[3] for o, _ in kept):
                continue  # the same object, seen again as another kind or a side peak
            kept.append((det, whole))
        # The colour is read around the whole box: a target cut by the frame's edge keeps its rim where it
        # is (its clipped box would put the rim inside the target, on its face).
        targets = [(whole, d.kind) for d, whole in kept]
        if self.colour_reader is None:
            reads = [read_colour(image, whole, kind) for whole, kind in targets]
        else:
            reads = self.colour_reader.read_all(image, targets)
        return [_with_colour(d, read) for (d, _), read in zip(kept, reads, strict=True)]

    def _detection_at(
        self, out: torch.Tensor, kind: int, j: int, i: int, score: float, width: int, height: int
    ) -> Detection:
        """The detection of heatmap cell (j, i) of channel `kind`, in the frame's pixels."""
        return self._detection_and_box(out, kind, j, i, score, width, height)[0]

    def _detection_and_box(
        self, out: torch.Tensor, kind: int, j: int, i: int, score: float, width: int, height: int
    ) -> tuple[Detection, tuple[float, float, float, float]]:
        """`_detection_at`, and its box as predicted, not clipped to the frame (it may reach past it)."""
        k = len(self.config.kinds)
        sx, sy = width / self.config.input_size, height / self.config.input_size
        u = (i + float(out[k, j, i])) * STRIDE * sx
        v = (j + float(out[k + 1, j, i])) * STRIDE * sy
        left, top, right, bottom = (torch.exp(out[k + 2 : k + 6, j, i]) * EDGE_SCALE_PX).tolist()
        whole = (u - left * sx, v - top * sy, u + right * sx, v + bottom * sy)
        bbox = (
            max(0.0, whole[0]),
            max(0.0, whole[1]),
            min(float(width), whole[2]),
            min(float(height), whole[3]),
        )
        return Detection(
            bbox_px=bbox, centre_px=(u, v), confidence=score, kind=self.config.kinds[kind]
        ), whole


def _with_colour(detection: Detection, read: ColourRead | None) -> Detection:
    if read is None:
        return detection
    return replace(detection, attribute=read.name, attribute_doubt=read.doubt)
