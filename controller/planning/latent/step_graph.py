"""The per-decision part of planning as one module: image → distances (+ presence).

The instruction's encoding and its goal z* are cached per instruction by the planner, so a decision
runs only E_img (FiLM-conditioned on E_inst when the model is), the fusion, f_θ for the 9 actions
and the distances. `StepGraph` is that part, run as it is on torch or exported to ONNX
(`export_step`) and run by ONNX Runtime; both backends get the same inputs.

    image (B, 3, S, S) float32 in [0, 1], text (B, d) E_inst, goal (B, d) z*
      → distances (B, 9) [, presence (B,) p(named target in view), with a presence head]
"""

from __future__ import annotations

import torch
from torch import nn

from controller.planning.latent.model import LatentDynamicsModel
from drone_inspect_core.onnx_runtime import OnnxModule

INPUTS = ("image", "text", "goal")


class StepGraph(nn.Module):
    """(image, text, goal) → (distances,) or (distances, presence): one decision's computation."""

    def __init__(self, model: LatentDynamicsModel) -> None:
        super().__init__()
        self.model = model
        self.eval()  # the exporter restores this module's mode onto the model afterwards

    @property
    def outputs(self) -> tuple[str, ...]:
        return ("distances", "presence") if self.model.presence is not None else ("distances",)

    def forward(
        self, image: torch.Tensor, text: torch.Tensor, goal: torch.Tensor
    ) -> tuple[torch.Tensor, ...]:
        z_s = self.model.fuse_state(self.model.encode_images(image, text), text)  # (B, d)
        distances = self.model.score(z_s, goal)[0]  # (B, 9)
        if self.model.presence is None:
            return (distances,)
        return distances, torch.sigmoid(self.model.presence_logits(z_s))  # (B, 9), (B,)


def export_step(step: StepGraph, image_size: int, threads: int | None = 1) -> OnnxModule:
    """`step` as an ONNX Runtime session, checked against torch on random inputs (OnnxBackendError)."""
    d = step.model.config.latent_dim
    generator = torch.Generator().manual_seed(0)
    examples = (
        torch.rand(2, 3, image_size, image_size, generator=generator),
        torch.randn(2, d, generator=generator),
        torch.randn(2, d, generator=generator),
    )
    return OnnxModule.export(step, examples, INPUTS, step.outputs, "latent planner", threads)
