"""Negative states: how sure the planner is that the target it was asked for is not in view.

A checkpoint with a presence head gives p(asked-for target in view) from z_s. It is judged
on pairs whose truth is known from the manifest:

- present: each test image asked for its named target (the same pairs as rank-1);
- absent: each test image asked for something its scene does not hold (a kind none of its
  targets has, or a kind with a colour none of that kind has), and each `empty` image (no
  target in view) asked for its scene's named target.

Reported: the area under the ROC curve (the chance that an absent pair scores lower than a
present one), accuracy at p = 0.5, the share of present pairs called absent (a mission
that would give up on a target in view) and of absent pairs called present.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
import torch

from controller.planning.latent.checkpoint import LoadedCheckpoint
from controller.training.data import ImageSet, to_float
from controller.training.pairs import absent_names, named_target_name
from controller.training.phrasing import describe


@dataclass(frozen=True)
class PresenceResult:
    n_present: int
    n_absent: int
    auroc: float
    accuracy: float
    false_absent_rate: float
    """Present pairs with p < 0.5: the target was in view and the model said it was not."""
    false_present_rate: float
    mean_absent_confidence: float
    """Mean 1 − p over the absent pairs."""

    def summary(self) -> dict[str, float | int]:
        return asdict(self)


@torch.inference_mode()
def presence_probabilities(
    ckpt: LoadedCheckpoint, images_u8: torch.Tensor, instructions: Sequence[str], batch: int = 128
) -> np.ndarray:
    """(N,) p(asked-for target in view) for N images, each with its own instruction."""
    model = ckpt.model.eval()
    out = []
    for i in range(0, len(images_u8), batch):
        text = model.encode_text(ckpt.tokenizer.batch(instructions[i : i + batch]))
        z_s = model.fuse_state(model.encode_images(to_float(images_u8[i : i + batch]), text), text)
        out.append(torch.sigmoid(model.presence_logits(z_s)))
    return torch.cat(out).numpy().astype(np.float64)


def absent_instructions(data: ImageSet, templates: Sequence[str], corpus: str, seed: int) -> list[str]:
    """One instruction per image asking for something its scene does not hold (seeded)."""
    rng = np.random.default_rng(seed)
    out = []
    for refs in data.targets:
        names = absent_names(refs)
        out.append(describe(names[int(rng.integers(len(names)))], templates, corpus, rng))
    return out


def empty_instructions(data: ImageSet, templates: Sequence[str], corpus: str, seed: int) -> list[str]:
    """One instruction per image asking for its scene's named target (which is out of view)."""
    rng = np.random.default_rng(seed)
    return [
        describe(named_target_name(refs, False), templates, corpus, rng) for refs in data.targets
    ]


def auroc(scores_pos: np.ndarray, scores_neg: np.ndarray) -> float:
    """P(a positive scores above a negative), ties counted half (the Mann–Whitney statistic)."""
    if len(scores_pos) == 0 or len(scores_neg) == 0:
        return float("nan")
    both = np.concatenate([scores_pos, scores_neg])
    order = both.argsort(kind="mergesort")
    ranks = np.empty(len(both))
    ranks[order] = np.arange(1, len(both) + 1)
    for value in np.unique(both):  # average ranks over ties
        tied = both == value
        ranks[tied] = ranks[tied].mean()
    n_pos = len(scores_pos)
    return float((ranks[:n_pos].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * len(scores_neg)))


def judge_presence(p_present: np.ndarray, p_absent: np.ndarray) -> PresenceResult:
    correct = int((p_present >= 0.5).sum() + (p_absent < 0.5).sum())
    n = len(p_present) + len(p_absent)
    return PresenceResult(
        n_present=len(p_present),
        n_absent=len(p_absent),
        auroc=auroc(p_present, p_absent),
        accuracy=correct / max(1, n),
        false_absent_rate=float((p_present < 0.5).mean()) if len(p_present) else float("nan"),
        false_present_rate=float((p_absent >= 0.5).mean()) if len(p_absent) else float("nan"),
        mean_absent_confidence=float((1.0 - p_absent).mean()) if len(p_absent) else float("nan"),
    )
