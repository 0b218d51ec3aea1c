"""Rank-1, per-axis accuracy and the confusion matrix of a trained planner on a dataset split.

"Training-style" instructions are those the model was trained with (the fixed
instruction, or the 30 training paraphrases); "heldout" are the paraphrases never
seen in training (the paper's vision + text generalisation); a FILE holds any
instructions, one per line (`{target}` slots are filled with the target's name).
Each test image is paired with one instruction drawn by a seeded generator.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from controller.planning.actions import NUM_ACTIONS
from controller.planning.latent.checkpoint import LoadedCheckpoint, load_checkpoint
from controller.planning.latent.data import ImageSet, load_images, load_index, to_float
from controller.planning.latent.instructions import builtin_templates, fill, read_templates
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.tokenizer import InstructionTokenizer

log = logging.getLogger(__name__)


@dataclass
class EvalResult:
    rank1: float  # both axes right
    x_accuracy: float
    z_accuracy: float
    confusion: list[list[int]]  # [true][predicted], action index order
    n: int
    instructions: str
    predictions: list[int] = field(default_factory=list)
    labels: list[int] = field(default_factory=list)
    offsets_px: list[list[float]] = field(default_factory=list)
    ids: list[str] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        keys = ("rank1", "x_accuracy", "z_accuracy", "n", "instructions", "confusion")
        return {k: getattr(self, k) for k in keys}


def instruction_templates(setting: str, trained_with: str) -> list[str]:
    """Templates for an evaluation setting: "train", "heldout" or a path to a text file."""
    if setting == "train":
        return builtin_templates("fixed" if trained_with == "fixed" else "train")
    if setting == "heldout":
        return builtin_templates("heldout")
    return read_templates(Path(setting))


def pair_instructions(kinds: Sequence[str], templates: Sequence[str], seed: int) -> list[str]:
    """One instruction per image, drawn with a seeded generator, filled with the image's target."""
    rng = np.random.default_rng(seed)
    picks = rng.integers(len(templates), size=len(kinds))
    return [fill(templates[int(p)], kind) for p, kind in zip(picks, kinds, strict=True)]


@torch.inference_mode()
def goal_embedding(
    model: LatentDynamicsModel, goal_images_u8: torch.Tensor, batch: int = 128
) -> torch.Tensor:
    """(d,) mean E_img over all goal images, in eval mode: the stored half of the goal prototype."""
    model.eval()
    parts = [
        model.encode_images(to_float(goal_images_u8[i : i + batch]))
        for i in range(0, len(goal_images_u8), batch)
    ]
    return torch.cat(parts).mean(dim=0)


@torch.inference_mode()
def predict_distances(
    model: LatentDynamicsModel,
    tokenizer: InstructionTokenizer,
    goal: torch.Tensor,
    images_u8: torch.Tensor,
    instructions: Sequence[str],
    batch: int = 128,
) -> torch.Tensor:
    """(N, 9) distances D(ẑ'_a, z*) for N images, each with its own instruction."""
    model.eval()
    out = []
    for i in range(0, len(images_u8), batch):
        ids = tokenizer.batch(instructions[i : i + batch])
        out.append(model(to_float(images_u8[i : i + batch]), ids, goal))
    return torch.cat(out)


def score(distances: torch.Tensor, data: ImageSet, setting: str) -> EvalResult:
    """Compare argmin-distance actions with the truth labels."""
    pred = distances.argmin(dim=1)
    true = data.labels
    confusion = torch.zeros(NUM_ACTIONS, NUM_ACTIONS, dtype=torch.long)
    confusion.index_put_((true, pred), torch.ones_like(true), accumulate=True)
    return EvalResult(
        rank1=float((pred == true).float().mean()),
        x_accuracy=float((pred // 3 == true // 3).float().mean()),
        z_accuracy=float((pred % 3 == true % 3).float().mean()),
        confusion=confusion.tolist(),
        n=len(data),
        instructions=setting,
        predictions=pred.tolist(),
        labels=true.tolist(),
        offsets_px=data.offsets.tolist(),
        ids=list(data.ids),
    )


def evaluate_loaded(
    ckpt: LoadedCheckpoint, data: ImageSet, setting: str = "train", seed: int = 0
) -> EvalResult:
    trained_with = str(ckpt.meta.get("train", {}).get("instructions", "varied"))
    templates = instruction_templates(setting, trained_with)
    instructions = pair_instructions(data.kinds, templates, seed)
    dist = predict_distances(ckpt.model, ckpt.tokenizer, ckpt.goal_image_embedding, data.images, instructions)
    return score(dist, data, setting)


def evaluate_checkpoint(
    model_dir: Path,
    data_dir: Path,
    setting: str = "train",
    split: str = "test",
    epsilon_px: float | None = None,
    seed: int = 0,
) -> EvalResult:
    """Load a checkpoint and a dataset split, and evaluate (ε defaults to the dataset's)."""
    ckpt = load_checkpoint(model_dir)
    index = load_index(data_dir)
    eps = index.default_epsilon_px() if epsilon_px is None else epsilon_px
    data = load_images(index.split(split), ckpt.config.image_size, eps, desc=split)
    result = evaluate_loaded(ckpt, data, setting, seed)
    log.info("%s on %s/%s (%d images): rank-1 %.4f", model_dir, data_dir, split, result.n, result.rank1)
    return result
