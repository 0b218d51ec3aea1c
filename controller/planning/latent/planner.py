"""`LatentPlanner`: paper Algorithm 2, one decision per call.

Per call: one image encoding, the instruction's encoding (cached per distinct
instruction, since a mission repeats the same one), z_s and z*, and all 9 candidate
actions scored in one batch; the chosen action is the argmin of the distances.

The per-decision part (`step_graph.StepGraph`: image → distances, presence) runs on torch or,
exported from the loaded checkpoint when the planner is made, on ONNX Runtime (`backend`):
the same distances within 1e-4 (checked at export and in tests/test_latent_onnx.py), about a
third of torch's latency on one thread (docs/reproduce/README.md).

Mirror test-time augmentation (`mirror`; default: the checkpoint's `planner.mirror_tta` in its
config.json, else off): each decision also scores the left-right mirror image and adds its
distances, left and right swapped back, in the same batch (about twice the work per decision).

Presence: a checkpoint with a presence head gives p(asked-for target in view) with every decision
(the mean with the mirror image's where it mirrors); `presence_threshold` is its config.json's
`planner.presence_threshold` (chosen on validation scenes by `dronectl calibrate-presence`), None
where it has none: below it the planner says the target is not in view (`in_view`).
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from collections.abc import Sequence
from functools import partial
from pathlib import Path

import cv2
import numpy as np
import torch

from controller.planning.actions import Action, with_mirror
from controller.planning.latent.checkpoint import load_checkpoint
from controller.planning.latent.errors import ImageInputError
from controller.planning.latent.image_encoder import fused_for_inference
from controller.planning.latent.step_graph import StepGraph, export_step
from drone_inspect_core.onnx_runtime import onnx_for

log = logging.getLogger(__name__)


class LatentPlanner:
    """Load a checkpoint folder once; `plan(image, instruction)` → (Action, distances (9,)).

    `backend`: "torch", "onnx" (needs onnxruntime; OnnxBackendError without it) or "auto" (ONNX
    when onnxruntime is installed and the export checks out, else torch; logged). `threads` is the
    thread count of either (None: the library's default).
    """

    def __init__(
        self,
        checkpoint_dir: str | Path,
        threads: int | None = 1,
        cache_size: int = 64,
        backend: str = "auto",
        mirror: bool | None = None,
    ) -> None:
        if threads is not None:
            torch.set_num_threads(threads)
        ckpt = load_checkpoint(Path(checkpoint_dir))
        self.checkpoint_dir = Path(checkpoint_dir)
        self.model = ckpt.model.eval()
        self.model.image_encoder = fused_for_inference(self.model.image_encoder)  # BN folded
        self.tokenizer = ckpt.tokenizer
        self.config = ckpt.config
        self.meta = ckpt.meta
        settings = ckpt.planner
        self.mirror = settings.mirror_tta if mirror is None else mirror
        self.presence_threshold = settings.presence_threshold if self.model.presence is not None else None
        """p(in view) below which the planner says the asked-for target is not in view; None: no verdict."""
        self._goal_image = ckpt.goal_image_embedding.unsqueeze(0)  # (1, d)
        self._cache: OrderedDict[str, tuple[torch.Tensor, torch.Tensor]] = OrderedDict()
        self._cache_size = cache_size
        self._step = StepGraph(self.model)
        export = partial(export_step, self._step, self.image_size, threads)
        self._onnx = onnx_for(backend, "latent planner", export)
        self.backend = "torch" if self._onnx is None else "onnx"

    @property
    def image_size(self) -> int:
        return self.config.image_size

    def plan(self, image: np.ndarray, instruction: str) -> tuple[Action, np.ndarray]:
        """The action minimising D(z_s + Δ_a, z*) and all 9 distances (float32, Action.index order)."""
        actions, distances = self.plan_batch([image], instruction)
        return actions[0], distances[0]

    def plan_batch(self, images: Sequence[np.ndarray], instruction: str) -> tuple[list[Action], np.ndarray]:
        """Plan for several images under one instruction: (actions, distances (N, 9))."""
        actions, dist, _ = self.plan_with_presence(images, instruction)
        return actions, dist

    @property
    def has_presence(self) -> bool:
        """Whether the checkpoint says how sure it is that the asked-for target is in view."""
        return self.model.presence is not None

    def in_view(self, presence: float | None) -> bool | None:
        """The planner's verdict on p(in view) at its calibrated threshold; None where it gives none."""
        if presence is None or self.presence_threshold is None:
            return None
        return bool(presence >= self.presence_threshold)

    @torch.inference_mode()
    def plan_with_presence(
        self, images: Sequence[np.ndarray], instruction: str
    ) -> tuple[list[Action], np.ndarray, np.ndarray | None]:
        """(actions, distances (N, 9), p(asked-for target in view) (N,) or None without a presence head)."""
        if len(images) == 0:
            raise ImageInputError("plan_batch needs at least one image")
        text, z_goal = self._instruction(instruction)
        x = torch.from_numpy(np.stack([self.prepare(img) for img in images]))  # (N, S, S, 3) uint8
        x = x.permute(0, 3, 1, 2).to(torch.float32).div_(255.0)  # (N, 3, S, S), channels-last strides
        n = x.shape[0]
        if self.mirror:
            x = torch.cat([x, x.flip(-1)])  # the mirror images in the same batch
        m = x.shape[0]
        inputs = (x, text.expand(m, -1), z_goal.expand(m, -1))
        if self._onnx is None:
            outputs = [t.numpy() for t in self._step(*inputs)]
        else:
            outputs = self._onnx.run(*(t.numpy() for t in inputs))
        dist = outputs[0].astype(np.float32, copy=False)  # (M, 9)
        presence = outputs[1].astype(np.float32, copy=False) if len(outputs) > 1 else None  # (M,)
        if self.mirror:
            dist = with_mirror(dist[:n], dist[n:])
            presence = None if presence is None else (presence[:n] + presence[n:]) / 2.0
        return [Action.from_index(int(i)) for i in dist.argmin(axis=1)], dist, presence

    def prepare(self, image: np.ndarray) -> np.ndarray:
        """Check an RGB uint8 H×W×3 image and resize it to the model's input size."""
        if not isinstance(image, np.ndarray):
            raise ImageInputError(f"image must be a numpy array, got {type(image).__name__}")
        if image.ndim != 3 or image.shape[2] != 3:
            raise ImageInputError(f"image must be RGB with shape (H, W, 3), got shape {image.shape}")
        if image.dtype != np.uint8:
            raise ImageInputError(f"image must be uint8 (0–255), got dtype {image.dtype}")
        if min(image.shape[:2]) < 8:
            raise ImageInputError(f"image of shape {image.shape} is too small to plan from")
        s = self.config.image_size
        if image.shape[:2] != (s, s):
            image = cv2.resize(image, (s, s), interpolation=cv2.INTER_AREA)
        return np.ascontiguousarray(image)

    def _instruction(self, instruction: str) -> tuple[torch.Tensor, torch.Tensor]:
        """(1, d) E_inst and (1, d) z* for an instruction, from a small LRU cache."""
        hit = self._cache.get(instruction)
        if hit is not None:
            self._cache.move_to_end(instruction)
            return hit
        ids = self.tokenizer.batch([instruction])  # raises InstructionError if empty
        text = self.model.encode_text(ids)
        entry = (text, self.model.fuse_state(self._goal_image, text))
        self._cache[instruction] = entry
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return entry
