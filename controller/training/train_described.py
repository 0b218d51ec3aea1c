"""One training step of the `described` target choice (pairs.py): any target in view, asked for in words.

Like `train._step`, with three differences: each sample's label is the move towards the
target its instruction asks for (not always the image's named target); E_img is FiLM-
conditioned on that instruction when the model is; and samples that ask for something not
in view train only the presence head (binary cross-entropy, `presence_weight`), never
the ranking, since no move is right for them. Goal images are encoded under an
instruction naming their own centred target, so the goal mean means "the asked-for
target is centred".
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch
import torch.nn.functional as F

from controller.planning.latent.model import LatentDynamicsModel, distance
from controller.planning.latent.tokenizer import InstructionTokenizer
from controller.training.augment import augment, label_exact, labels_of
from controller.training.config import TrainConfig
from controller.training.data import ImageSet, to_float
from controller.training.distill import Teacher, presence_distillation, ranking_distillation
from controller.training.instructions import builtin_templates
from controller.training.losses import LossTerms, total_loss
from controller.training.pairs import DescriptionSampler, named_target_name
from controller.training.phrasing import fill_phrase, noun_phrase, synonyms
from drone_inspect_core.vocabulary import Vocabulary


def ranking_terms(
    model: LatentDynamicsModel,
    cfg: TrainConfig,
    z_s: torch.Tensor,
    z_goal: torch.Tensor,
    labels: torch.Tensor,
) -> tuple[LossTerms, torch.Tensor]:
    """The paper's four losses for states z_s (B, d) against goals z_goal (B, d), and the (B, 9) distances."""
    d_all, deltas = model.score(z_s, z_goal)  # (B, 9), (B, 9, d)
    rows = torch.arange(len(labels), device=labels.device)
    terms = total_loss(
        d_now=distance(z_s, z_goal, model.config.distance),
        d_all=d_all,
        target=labels,
        delta_true=deltas[rows, labels],
        g_true=model.global_shifts()[labels],
        weights=cfg.weights,
        margin=cfg.margin,
        temperature=cfg.temperature,
    )
    return terms, d_all


def model_input(model: LatentDynamicsModel, images: torch.Tensor, channels_last: bool) -> torch.Tensor:
    """A CPU-augmented batch on the model's device, in the memory order training uses."""
    fmt = torch.channels_last if channels_last else torch.contiguous_format
    return images.to(model.device, memory_format=fmt)


def goal_ids(
    tokenizer: InstructionTokenizer, goals: ImageSet, corpus: str, vocabulary: Vocabulary | None = None
) -> torch.Tensor:
    """(G, L) ids of the fixed instruction naming each goal image's centred target (stored goal mean)."""
    template = builtin_templates("fixed")[0]
    texts = []
    for refs in goals.targets:
        name = named_target_name(refs, with_colour=False)
        texts.append(fill_phrase(template, noun_phrase(name, synonyms(name.kind, corpus, vocabulary)[0])))
    return tokenizer.batch(texts)


def step_described(
    model: LatentDynamicsModel,
    cfg: TrainConfig,
    data: ImageSet,
    goals: ImageSet,
    idx: torch.Tensor,
    g_idx: torch.Tensor,
    sampler: DescriptionSampler,
    size_px: tuple[int, int],
    eps: float,
    gen: torch.Generator,
    rng: np.random.Generator,
    teacher: Teacher | None = None,
) -> tuple[LossTerms, torch.Tensor, torch.Tensor]:
    """Forward one batch; return its loss terms, the present samples' (P, 9) distances and labels.

    With a `teacher` the total also holds `cfg.distill_weight` times the distillation terms
    (`controller.training.distill`); the sampler must then spell the teacher's tokens too."""
    b = len(idx)
    pairs = sampler.sample([data.targets[i] for i in idx.tolist()], rng)
    batch = augment(to_float(data.images[idx]), pairs.offsets_px, size_px, eps, cfg.augment, gen)
    goal_cfg = replace(cfg.augment, translate=0.0, hflip=False)
    goal_x = augment(to_float(goals.images[g_idx]), goals.offsets[g_idx], size_px, eps, goal_cfg, gen).images
    if label_exact(cfg.augment):
        labels = labels_of(batch.offsets_px, eps)
    else:
        labels = labels_of(pairs.offsets_px, eps)
    goal_text_ids = sampler.named([goals.targets[i] for i in g_idx.tolist()], rng)
    width = max(pairs.ids.shape[1], goal_text_ids.shape[1])
    ids = torch.cat(
        [
            F.pad(pairs.ids, (0, width - pairs.ids.shape[1])),
            F.pad(goal_text_ids, (0, width - goal_text_ids.shape[1])),
        ]
    )
    x = model_input(model, torch.cat([batch.images, goal_x]), cfg.channels_last)
    text_all = model.encode_text(ids.to(x.device))  # (B + G, d)
    img = model.encode_images(x, text_all)  # (B + G, d), one BN batch
    text = text_all[:b]
    goal_mean = img[b:].mean(dim=0, keepdim=True)  # (1, d)
    z_s = model.fuse_state(img[:b], text)  # (B, d)
    z_goal = model.fuse_state(goal_mean.expand(b, -1), text)  # (B, d)
    present = pairs.present.to(x.device)
    keep = present.nonzero().squeeze(1)
    labels = labels.to(x.device)[keep]
    terms, d_all = ranking_terms(model, cfg, z_s[keep], z_goal[keep], labels)
    logits = model.presence_logits(z_s) if model.presence is not None else None
    if logits is not None and cfg.presence_weight > 0:
        presence = F.binary_cross_entropy_with_logits(logits, present.float())
        terms = replace(terms, total=terms.total + cfg.presence_weight * presence)
    if teacher is not None:
        if pairs.teacher_ids is None:
            raise ValueError("distillation: the sampler was made without the teacher's tokenizer")
        d_teacher, logits_teacher = teacher.scores(x[:b], pairs.teacher_ids)
        taught = ranking_distillation(d_all, d_teacher[keep], cfg.temperature)
        if logits is not None and logits_teacher is not None:
            taught = taught + cfg.presence_weight * presence_distillation(logits, logits_teacher)
        terms = replace(terms, total=terms.total + cfg.distill_weight * taught)
    return terms, d_all, labels
