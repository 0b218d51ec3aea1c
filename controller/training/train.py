"""Training loop of paper Algorithm 1: four losses, Adam, best checkpoint by validation accuracy.

Per batch: encode the batch's images together with `goal_sample` goal images (one
forward pass, so batch-norm sees one batch), take the goal images' mean embedding,
encode each sample's instruction, fuse to z_s and z*, score all 9 actions, and
minimise L_total. After each epoch the validation split (20 % of `train`) is scored
with the stored-goal rule used at inference; the best epoch is saved.
"""

from __future__ import annotations

import copy
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from controller.evaluation.evaluate import (
    goal_embedding,
    pair_described,
    pair_instructions,
    predict_distances,
    score,
)
from controller.evaluation.plots import plot_curves
from controller.planning.latent.checkpoint import save_checkpoint
from controller.planning.latent.config import ModelConfig
from controller.planning.latent.errors import TrainingDataError
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.tokenizer import InstructionTokenizer
from controller.training.augment import augment, label_exact, labels_of
from controller.training.config import TrainConfig
from controller.training.data import (
    DatasetIndex,
    ImageSet,
    load_images,
    load_index,
    split_train_val,
    to_float,
)
from controller.training.distill import Teacher
from controller.training.finetune import TrainingWords, check_start, start_from, training_words
from controller.training.instructions import builtin_templates, fill, tokenizer_corpus
from controller.training.losses import LossTerms
from controller.training.pairs import DescriptionSampler
from controller.training.phrasing import all_phrasings
from controller.training.train_described import goal_ids as _goal_ids
from controller.training.train_described import model_input, ranking_terms
from controller.training.train_described import step_described as _step_described
from drone_inspect_core.files import claimed_dir, write_json_atomic
from drone_inspect_core.vocabulary import shipped_vocabulary

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


def _merged_index(data_dirs: Sequence[Path]) -> DatasetIndex:
    """One index over several dataset folders (rows in folder order); all must share the image size."""
    indices = [load_index(d) for d in data_dirs]
    first = indices[0]
    for other in indices[1:]:
        if (other.width_px, other.height_px) != (first.width_px, first.height_px):
            raise TrainingDataError(
                f"{other.root}: images are {other.width_px}×{other.height_px} px, "
                f"{first.root} has {first.width_px}×{first.height_px}; train on one image size"
            )
    if len(indices) == 1:
        return first
    meta = {**first.meta, "merged": [{"path": str(i.root), "meta": i.meta} for i in indices]}
    for key in ("train_scene_seeds", "test_scene_seeds"):  # every folder's, so "unseen" checks see them all
        meta[key] = sorted({s for i in indices for s in i.meta.get(key, [])})
    rows = tuple(r for i in indices for r in i.rows)
    return DatasetIndex(first.root, meta, rows, first.width_px, first.height_px)


def train(
    data_dir: Path | Sequence[Path],
    out_dir: Path,
    model_cfg: ModelConfig,
    cfg: TrainConfig,
    progress: bool = True,
    device: str = "cpu",
    init_dir: Path | None = None,
) -> TrainResult:
    """Train on `data_dir` (a collected dataset folder, or several); write the best checkpoint + metrics.

    `init_dir`: fine-tune that checkpoint (`controller.training.finetune`: its model and tokenizer,
    grown by the words of the kinds the data adds; `model_cfg` is then the checkpoint's).

    `device` is where the model trains ("cpu", "cuda", "cuda:1", or "auto": a GPU if torch sees
    one). Data, augmentation and their random draws stay on the CPU either way, so a GPU run
    draws the same samples; its arithmetic differs in the last bits. The checkpoint is written
    from a CPU copy, the same format as ever.
    """
    dev = resolve_device(device)
    data_dirs = [Path(data_dir)] if isinstance(data_dir, str | Path) else [Path(d) for d in data_dir]
    if not data_dirs:
        raise TrainingDataError("no dataset folder to train on")
    # A bad starting checkpoint, dataset or kind is said before the run folder exists.
    if init_dir is not None:
        model_cfg = check_start(init_dir)
    teacher = (
        None
        if cfg.distill_from is None
        else Teacher.load(Path(cfg.distill_from), model_cfg.image_size, dev, cfg.channels_last)
    )
    index = _merged_index(data_dirs)
    words = training_words(data_dirs, init_dir)
    # The run folder must be new or empty, and a run that fails before writing leaves none behind.
    with claimed_dir(out_dir, "run folder") as claimed:
        return _fit(index, data_dirs[0], claimed, model_cfg, cfg, progress, dev, words, init_dir, teacher)


def _fit(
    index: DatasetIndex,
    data_dir: Path,
    out_dir: Path,
    model_cfg: ModelConfig,
    cfg: TrainConfig,
    progress: bool,
    dev: torch.device,
    words: TrainingWords,
    init_dir: Path | None,
    teacher: Teacher | None = None,
) -> TrainResult:
    """`train` once the data is indexed and the run folder claimed."""
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    described = cfg.target_choice == "described"
    if described and model_cfg.conditioning == "none" and not model_cfg.presence_head:
        log.warning("target_choice 'described' without FiLM or a presence head: the words reach z_s only")
    eps = index.default_epsilon_px() if cfg.epsilon_px is None else cfg.epsilon_px
    rows = index.split("train") + (index.split("goal") if cfg.goal_as_samples else [])
    if len(rows) * (1.0 - cfg.val_fraction) < cfg.batch_size // 4:  # said before minutes of loading
        raise TrainingDataError(
            f"{data_dir}: about {int(len(rows) * (1.0 - cfg.val_fraction))} training images for a batch of "
            f"{cfg.batch_size}; need at least a quarter batch"
        )
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

    templates = builtin_templates("fixed" if cfg.instructions == "fixed" else "train")
    corpus = "fixed" if cfg.instructions == "fixed" else "train"
    vocabulary = words.vocabulary
    if described:
        text_corpus = all_phrasings(builtin_templates("fixed") + templates, corpus, vocabulary)
    else:
        own = sorted(set(pool.kinds) - set(shipped_vocabulary().kinds))  # none: as ever
        text_corpus = tokenizer_corpus() + [fill(t, k) for k in own for t in templates]
    if init_dir is not None:
        start = start_from(init_dir, text_corpus)
        tokenizer, model_cfg, model = start.tokenizer, start.config, start.model
    else:
        tokenizer = InstructionTokenizer.train(text_corpus, model_cfg.vocab_size, model_cfg.max_tokens)
        model_cfg = replace(model_cfg, vocab_size=tokenizer.vocab_size)
        model = LatentDynamicsModel(model_cfg, cfg.shift_init_std)
    model = model.to(dev, memory_format=torch.channels_last if cfg.channels_last else torch.preserve_format)
    rng = np.random.default_rng(cfg.seed)
    sampler: _InstructionSampler | DescriptionSampler
    if described:
        sampler = DescriptionSampler(
            tokenizer,
            templates,
            corpus,
            cfg.absent_fraction,
            cfg.named_fraction,
            vocabulary,
            None if teacher is None else teacher.tokenizer,
        )
        val_instructions = pair_described(val_set.targets, templates, corpus, cfg.seed, vocabulary)
        goal_ids = _goal_ids(tokenizer, goals, corpus, vocabulary)
    else:
        sampler = _InstructionSampler(tokenizer, templates, pool.kinds)
        val_instructions = pair_instructions(val_set.kinds, templates, cfg.seed)
        goal_ids = None

    steps_per_epoch = math.ceil(len(train_set) / cfg.batch_size)
    optimiser = torch.optim.Adam(model.parameters(), lr=cfg.learning_rate)
    total_steps = cfg.epochs * steps_per_epoch
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimiser,
        (lambda s: 0.5 * (1.0 + math.cos(math.pi * s / total_steps)))
        if cfg.lr_schedule == "cosine"
        else (lambda s: 1.0),
    )
    # The model that is validated and saved: the trained weights, or their moving average.
    ema = (
        torch.optim.swa_utils.AveragedModel(
            model, multi_avg_fn=torch.optim.swa_utils.get_ema_multi_avg_fn(cfg.ema_decay), use_buffers=True
        )
        if cfg.ema_decay > 0
        else None
    )
    size_px = (index.width_px, index.height_px)
    meta: dict[str, Any] = {
        "train": cfg.to_dict(),
        "epsilon_px": eps,
        "dataset": {"path": str(Path(data_dir).resolve()), "meta": index.meta},
        "counts": {"goal": len(goals), "train": len(train_set), "val": len(val_set)},
        "kinds": words.own_kinds,
        "init": None if init_dir is None else str(init_dir),
    }
    history: list[dict[str, float]] = []
    best_acc, best_epoch, seen = -1.0, 0, 0
    start, cpu_start = time.perf_counter(), time.process_time()
    bar = tqdm(range(1, cfg.epochs + 1), desc="epochs", disable=not progress)
    for epoch in bar:
        model.train()
        order = _epoch_order(train_set.kinds, cfg.balance_kinds, gen)
        sums = dict.fromkeys(("total", "dir", "rank", "cons", "reg"), 0.0)
        correct = n_scored = 0
        for b in range(steps_per_epoch):
            idx = order[b * cfg.batch_size : (b + 1) * cfg.batch_size]
            g_idx = torch.randint(len(goals), (cfg.goal_sample,), generator=gen)
            if isinstance(sampler, DescriptionSampler):
                terms, d_all, labels = _step_described(
                    model, cfg, train_set, goals, idx, g_idx, sampler, size_px, eps, gen, rng, teacher
                )
            else:
                terms, d_all, labels = _step(
                    model, cfg, train_set, goals, idx, g_idx, sampler, size_px, eps, gen
                )
            optimiser.zero_grad(set_to_none=True)
            terms.total.backward()
            optimiser.step()
            schedule.step()
            if ema is not None:
                ema.update_parameters(model)
            for k, v in terms.as_floats().items():
                sums[k] += v * len(idx)
            correct += int((d_all.detach().argmin(dim=1) == labels).sum())
            n_scored += len(labels)
            seen += len(idx) + cfg.goal_sample
        kept = model if ema is None else ema.module
        goal = goal_embedding(kept, goals.images, goal_ids)
        val = score(
            predict_distances(kept, tokenizer, goal, val_set.images, val_instructions), val_set, "train"
        )
        row = {k: v / len(train_set) for k, v in sums.items()}
        row.update(epoch=epoch, train_accuracy=correct / max(1, n_scored), val_accuracy=val.rank1)
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
            on_cpu = kept if dev.type == "cpu" else copy.deepcopy(kept).cpu()
            save_checkpoint(out_dir, on_cpu, tokenizer, goal, meta)
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
        "device": str(dev),
        "model": model_cfg.to_dict(),
        **meta,
        "history": history,
    }
    write_json_atomic(out_dir / METRICS_FILE, metrics)
    plot_curves(history, out_dir / CURVES_FILE)
    log.info("trained in %.0f s; best val rank-1 %.4f at epoch %d", seconds, best_acc, best_epoch)
    return result


def resolve_device(name: str) -> torch.device:
    """`--device`: cpu, cuda[:N] or auto (a GPU if torch sees one, else the CPU); ValueError if absent."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(name)
    except RuntimeError as exc:
        raise ValueError(f"unknown device {name!r}; use cpu, cuda, cuda:N or auto") from exc
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {name!r} asked for, but torch sees no CUDA GPU here ({torch.__version__})")
    if dev.type not in ("cpu", "cuda"):
        raise ValueError(f"device {name!r}: training runs on cpu or cuda")
    return dev


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
    x = model_input(model, torch.cat([batch.images, goal_x]), cfg.channels_last)
    labels = labels.to(x.device)
    img = model.encode_images(x)  # (B + G, d), one batch-norm batch
    goal_mean = img[b:].mean(dim=0, keepdim=True)  # (1, d): this step's goal image mean
    ids = sampler.sample([data.kinds[i] for i in idx.tolist()], gen)
    text = model.encode_text(ids.to(x.device))  # (B, d)
    z_s = model.fuse_state(img[:b], text)  # (B, d)
    z_goal = model.fuse_state(goal_mean.expand(b, -1), text)  # (B, d)
    terms, d_all = ranking_terms(model, cfg, z_s, z_goal, labels)
    return terms, d_all, labels
