"""Distillation: a finished planner checkpoint (the teacher) scores every training batch, and the
student learns its scores beside the paper's losses (`TrainConfig.distill_from`, `distill_weight`).

The teacher sees what the student sees: the same augmented images and the same instruction (spelt
with the teacher's own tokenizer, so a teacher trained on another vocabulary still reads the words
it knows). It scores them as it plans: eval mode, its stored goal image mean, no mirror image.
Two terms, over the batch:
- the ranking: KL(p_teacher ‖ p_student) with p = softmax(−D/τ) over the nine moves, τ the ranking
  loss's temperature, on the samples whose asked-for target is in view (the ranking is trained on
  those alone);
- presence (when both models have the head): binary cross-entropy of the student's logit against the
  teacher's probability, on every sample, weighted as the presence loss is (`presence_weight`).

Why (docs/targets.md, "Over seeds"): trained from scratch, one seed of three falls 4–7 points behind
on the held-out look while all three fit the training scenes alike; a teacher's scores on the same
augmented images say more about each image than its one label does.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F

from controller.planning.latent.checkpoint import load_checkpoint
from controller.planning.latent.errors import PlannerCheckpointError
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.tokenizer import InstructionTokenizer


@dataclass(frozen=True)
class Teacher:
    """A frozen planner checkpoint that scores training batches (module docstring)."""

    model: LatentDynamicsModel
    tokenizer: InstructionTokenizer
    goal: torch.Tensor  # (d,): its stored goal image mean

    @classmethod
    def load(cls, folder: Path, image_size: int, device: torch.device, channels_last: bool) -> Teacher:
        """The checkpoint in `folder`, checked as any planner checkpoint is; PlannerCheckpointError when it
        is not one, or takes another input size than the student (`image_size`)."""
        ckpt = load_checkpoint(Path(folder))
        if ckpt.config.image_size != image_size:
            raise PlannerCheckpointError(
                f"teacher {folder} takes {ckpt.config.image_size} px images, the student {image_size} px: "
                "distillation needs the same input"
            )
        fmt = torch.channels_last if channels_last else torch.preserve_format
        model = ckpt.model.to(device, memory_format=fmt).eval().requires_grad_(False)
        return cls(model, ckpt.tokenizer, ckpt.goal_image_embedding.to(device))

    @property
    def has_presence(self) -> bool:
        return self.model.presence is not None

    @torch.no_grad()
    def scores(self, images: torch.Tensor, ids: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(B, 9) distances to the goal and (B,) presence logits (None without the head) of a batch."""
        text = self.model.encode_text(ids.to(images.device))
        z_s = self.model.fuse_state(self.model.encode_images(images, text), text)
        z_goal = self.model.fuse_state(self.goal.expand_as(text), text)
        d_all = self.model.score(z_s, z_goal)[0]
        return d_all, (self.model.presence_logits(z_s) if self.has_presence else None)


def ranking_distillation(
    d_student: torch.Tensor, d_teacher: torch.Tensor, temperature: float
) -> torch.Tensor:
    """KL(softmax(−d_teacher/τ) ‖ softmax(−d_student/τ)), averaged over the batch; 0 for an empty one."""
    if len(d_student) == 0:
        return d_student.sum()
    log_student = F.log_softmax(-d_student / temperature, dim=1)
    log_teacher = F.log_softmax(-d_teacher / temperature, dim=1)
    return F.kl_div(log_student, log_teacher, log_target=True, reduction="batchmean")


def presence_distillation(logits_student: torch.Tensor, logits_teacher: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy of the student's presence logits against the teacher's probabilities."""
    return F.binary_cross_entropy_with_logits(logits_student, torch.sigmoid(logits_teacher))
