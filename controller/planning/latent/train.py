"""Training loop of paper Algorithm 1: four losses, Adam, best checkpoint by validation accuracy.

Per batch: encode the batch's images together with `goal_sample` goal images (one
forward pass, so batch-norm sees one batch), take the goal images' mean embedding,
encode each sample's instruction, fuse to z_s and z*, score all 9 actions, and
minimise L_total. After each epoch the validation split (20 % of `train`) is scored
with the stored-goal rule used at inference; the best epoch is saved.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

from controller.planning.latent.augment import augment, label_exact, labels_of
from controller.planning.latent.checkpoint import save_checkpoint
from controller.planning.latent.config import ModelConfig, TrainConfig
from controller.planning.latent.data import ImageSet, load_images, load_index, split_train_val, to_float
from controller.planning.latent.errors import TrainingDataError
from controller.planning.latent.evaluate import goal_embedding, pair_instructions, predict_distances, score
from controller.planning.latent.instructions import builtin_templates, fill, tokenizer_corpus
from controller.planning.latent.losses import LossTerms, distance, total_loss
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.plots import plot_curves
from controller.planning.latent.tokenizer import InstructionTokenizer

log = logging.getLogger(__name__)
METRICS_FILE = "metrics.json"
CURVES_FILE = "curves.png"


@dataclass(frozen=True)
class TrainResult:
    out_dir: Path
    best_val_accuracy: float
    best_epoch: int
    seconds: float
    images_per_s: float


class _InstructionSampler:
    """Token ids of every (target kind, template) pair, and per-sample random picks among them."""

    def __init__(self, tokenizer: InstructionTokenizer, templates: list[str], kinds: list[str]) -> None:
        self.kinds = sorted(set(kinds))
        self.n_templates = len(templates)
        texts = [fill(t, k) for k in self.kinds for t in templates]
        self.ids = tokenizer.batch(texts)  # (K·T, L)

    def sample(self, kinds: list[str], gen: torch.Generator) -> torch.Tensor:
        kind_idx = torch.tensor([self.kinds.index(k) for k in kinds])
        pick = torch.randint(self.n_templates, (len(kinds),), generator=gen)
        rows = self.ids[kind_idx * self.n_templates + pick]  # (B, L)
        return rows[:, : int(rows.ne(0).sum(dim=1).max())]


def train(
    data_dir: Path, out_dir: Path, model_cfg: ModelConfig, cfg: TrainConfig, progress: bool = True
) -> TrainResult:
    """Train on `data_dir` (a collected dataset folder); write the best checkpoint + metrics to `out_dir`."""
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    index = load_index(data_dir)
    eps = index.default_epsilon_px() if cfg.epsilon_px is None else cfg.epsilon_px
    rows = index.split("train") + (index.split("goal") if cfg.goal_as_samples else [])
    pool = load_images(rows, model_cfg.image_size, eps, desc="train", progress=progress)
    tr_idx, va_idx = split_train_val(len(pool), cfg.val_fraction, cfg.seed)
    train_set, val_set = pool.subset(tr_idx), pool.subset(va_idx)
    if cfg.goal_as_samples:  # the prototype uses only goal images on the training side of the split
        goals = train_set.subset([i for i, sp in enumerate(train_set.splits) if sp == "goal"])
    else:
        goals = load_images(index.split("goal"), model_cfg.image_size, eps, desc="goal", progress=progress)
    if len(goals) == 0:
        raise TrainingDataError(f"{data_dir}: no goal images for the goal prototype")
    if len(train_set) < cfg.batch_size // 4:
        raise TrainingDataError(
            f"{data_dir}: only {len(train_set)} training images; need at least a quarter batch"
        )

    tokenizer = InstructionTokenizer.train(tokenizer_corpus(), model_cfg.vocab_size, model_cfg.max_tokens)
    model_cfg = replace(model_cfg, vocab_size=tokenizer.vocab_size)
    model = LatentDynamicsModel(model_cfg)
    templates = builtin_templates("fixed" if cfg.instructions == "fixed" else "train")
    sampler = _InstructionSampler(tokenizer, templates, pool.kinds)
    val_instructions = pair_instructions(val_set.kinds, templates, cfg.seed)

    steps_per_epoch = math.ceil(len(train_set) / cfg.batch_size)
    optimiser = torch.optim.Adam(model.parameters(), lr=cfg.learning_rate)
    total_steps = cfg.epochs * steps_per_epoch
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimiser,
        (lambda s: 0.5 * (1.0 + math.cos(math.pi * s / total_steps)))
        if cfg.lr_schedule == "cosine"
        else (lambda s: 1.0),
    )
    size_px = (index.width_px, index.height_px)
    meta: dict[str, Any] = {
        "train": cfg.to_dict(),
        "epsilon_px": eps,
        "dataset": {"path": str(Path(data_dir).resolve()), "meta": index.meta},
        "counts": {"goal": len(goals), "train": len(train_set), "val": len(val_set)},
    }
    history: list[dict[str, float]] = []
    best_acc, best_epoch, seen = -1.0, 0, 0
    start, cpu_start = time.perf_counter(), time.process_time()
    bar = tqdm(range(1, cfg.epochs + 1), desc="epochs", disable=not progress)
    for epoch in bar:
        model.train()
        order = _epoch_order(train_set.kinds, cfg.balance_kinds, gen)
        sums = dict.fromkeys(("total", "dir", "rank", "cons", "reg"), 0.0)
        correct = 0
        for b in range(steps_per_epoch):
            idx = order[b * cfg.batch_size : (b + 1) * cfg.batch_size]
            g_idx = torch.randint(len(goals), (cfg.goal_sample,), generator=gen)
            terms, d_all, labels = _step(model, cfg, train_set, goals, idx, g_idx, sampler, size_px, eps, gen)
            optimiser.zero_grad(set_to_none=True)
            terms.total.backward()
            optimiser.step()
            schedule.step()
            for k, v in terms.as_floats().items():
                sums[k] += v * len(idx)
            correct += int((d_all.detach().argmin(dim=1) == labels).sum())
            seen += len(idx) + cfg.goal_sample
        goal = goal_embedding(model, goals.images)
        val = score(
            predict_distances(model, tokenizer, goal, val_set.images, val_instructions), val_set, "train"
        )
        row = {k: v / len(train_set) for k, v in sums.items()}
        row.update(epoch=epoch, train_accuracy=correct / len(train_set), val_accuracy=val.rank1)
        row.update(lr=schedule.get_last_lr()[0], seconds=time.perf_counter() - start)
        history.append(row)
        if val.rank1 > best_acc:
            best_acc, best_epoch = val.rank1, epoch
            meta["best"] = {
                "epoch": epoch,
                "val_accuracy": val.rank1,
                "val_x": val.x_accuracy,
                "val_z": val.z_accuracy,
            }
            save_checkpoint(out_dir, model, tokenizer, goal, meta)
        bar.set_postfix(
            loss=f"{row['total']:.3f}", train=f"{row['train_accuracy']:.3f}", val=f"{val.rank1:.3f}"
        )
        log.log(logging.DEBUG if progress else logging.INFO, "epoch %d: %s", epoch, _brief(row))
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu_start
    result = TrainResult(out_dir, best_acc, best_epoch, seconds, seen / seconds)
    metrics = {
        "best_epoch": best_epoch,
        "best_val_accuracy": best_acc,
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,  # all threads; on an otherwise idle machine wall ≈ cpu / threads
        "images_per_s": result.images_per_s,
        "model": model_cfg.to_dict(),
        **meta,
        "history": history,
    }
    (out_dir / METRICS_FILE).write_text(json.dumps(metrics, indent=2) + "\n")
    plot_curves(history, out_dir / CURVES_FILE)
    log.info("trained in %.0f s; best val rank-1 %.4f at epoch %d", seconds, best_acc, best_epoch)
    return result


def _epoch_order(kinds: list[str], balance: bool, gen: torch.Generator) -> torch.Tensor:
    """One epoch's sample order: a permutation, or (balance) len(kinds) draws with equal mass per kind."""
    n = len(kinds)
    if not balance:
        return torch.randperm(n, generator=gen)
    names = sorted(set(kinds))
    kind_idx = torch.tensor([names.index(k) for k in kinds])
    weights = 1.0 / torch.bincount(kind_idx).float()[kind_idx]  # (N,)
    return torch.multinomial(weights, n, replacement=True, generator=gen)


def _brief(row: dict[str, float]) -> str:
    return " ".join(f"{k}={v:.4g}" for k, v in row.items())


def _step(
    model: LatentDynamicsModel,
    cfg: TrainConfig,
    data: ImageSet,
    goals: ImageSet,
    idx: torch.Tensor,
    g_idx: torch.Tensor,
    sampler: _InstructionSampler,
    size_px: tuple[int, int],
    eps: float,
    gen: torch.Generator,
) -> tuple[LossTerms, torch.Tensor, torch.Tensor]:
    """Forward one batch; return its loss terms, (B, 9) distances and the (B,) labels it was scored on.

    With label-exact geometry the batch's labels are recomputed from the moved offsets; the goal
    images of the prototype get only the paper's label-preserving set (they must stay centred).
    """
    b = len(idx)
    batch = augment(to_float(data.images[idx]), data.offsets[idx], size_px, eps, cfg.augment, gen)
    goal_cfg = replace(cfg.augment, translate=0.0, hflip=False)
    goal_x = augment(to_float(goals.images[g_idx]), goals.offsets[g_idx], size_px, eps, goal_cfg, gen).images
    labels = labels_of(batch.offsets_px, eps) if label_exact(cfg.augment) else data.labels[idx]
    img = model.encode_images(torch.cat([batch.images, goal_x]))  # (B + G, d), one batch-norm batch
    goal_mean = img[b:].mean(dim=0, keepdim=True)  # (1, d): this step's goal image mean
    text = model.encode_text(sampler.sample([data.kinds[i] for i in idx.tolist()], gen))  # (B, d)
    z_s = model.fuse_state(img[:b], text)  # (B, d)
    z_goal = model.fuse_state(goal_mean.expand(b, -1), text)  # (B, d)
    d_all, deltas = model.score(z_s, z_goal)  # (B, 9), (B, 9, d)
    rows = torch.arange(b)
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
    return terms, d_all, labels
