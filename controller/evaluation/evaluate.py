"""Rank-1, per-axis accuracy and the confusion matrix of a trained planner on a dataset split.

"Training-style" instructions are those the model was trained with (the fixed
instruction, or the 30 training paraphrases); "heldout" are the paraphrases never
seen in training (the paper's vision + text generalisation); a FILE holds any
instructions, one per line (`{target}` slots are filled with the target's name), or
`kind: phrase` lines (each image gets a phrase written for its named target's kind), or is an
operator-words YAML file (`controller.evaluation.operator_words`: templates, words per kind and
colour). Each test image is paired with one instruction drawn by a seeded generator.

`flown` scores the same instructions a second time as the loop flies them: understood by the
keyword parser and heard by the planner in its trained words (`operator_words.as_flown`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from controller.evaluation.operator_words import (
    UNDERSTOOD,
    Flown,
    as_flown,
    is_operator_words_file,
    load_operator_words,
    pair_operator_words,
)
from controller.evaluation.presence import (
    Ask,
    flown_asker,
    judge_presence,
    kind_presence_pairs,
    presence_pairs,
    presence_threshold,
)
from controller.planning.actions import NUM_ACTIONS, with_mirror
from controller.planning.latent.checkpoint import LoadedCheckpoint, load_checkpoint
from controller.planning.latent.errors import InstructionError
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.tokenizer import InstructionTokenizer
from controller.training.data import ImageSet, TargetRef, load_images, load_index, to_float
from controller.training.instructions import builtin_templates, fill, read_templates
from controller.training.pairs import named_target_name
from controller.training.phrasing import describe, is_kind_phrase_file, read_kind_phrases
from drone_inspect_core.own_kinds import words_only
from drone_inspect_core.vocabulary import Vocabulary, vocabulary_with

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
    by_targets_in_view: dict[str, dict[str, float]] = field(default_factory=dict)
    """Rank-1 by how many targets the image shows ("1", "2", "3", "4"): {"n", "rank1"}."""
    by_kind_and_targets: dict[str, dict[str, float]] = field(default_factory=dict)
    """Rank-1 by the named target's kind and how many targets the image shows ("gauge/2"): {"n", "rank1"}."""
    presence: dict[str, float | int] | None = None
    """`presence.PresenceResult.summary()` for a checkpoint with a presence head."""
    presence_by_kind: dict[str, float | int] | None = None
    """The same, asked as the loop asks before it takes a detection for the target: by the kind alone
    (`presence.kind_presence_pairs`)."""
    correct: list[bool] = field(default_factory=list)
    """Per image: the right action, from an instruction the loop understood (as flown)."""
    parsed: dict[str, int] | None = None
    """As flown: how many instructions the loop understood, refused and misread (`operator_words`)."""

    def summary(self) -> dict[str, Any]:
        keys = (
            "rank1",
            "x_accuracy",
            "z_accuracy",
            "n",
            "instructions",
            "confusion",
            "by_targets_in_view",
            "by_kind_and_targets",
        )
        out = {k: getattr(self, k) for k in keys}
        if self.presence is not None:
            out["presence"] = self.presence
        if self.presence_by_kind is not None:
            out["presence_by_kind"] = self.presence_by_kind
        if self.parsed is not None:
            out["parsed"] = self.parsed
        return out


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
    model: LatentDynamicsModel,
    goal_images_u8: torch.Tensor,
    goal_ids: torch.Tensor | None = None,
    batch: int = 128,
) -> torch.Tensor:
    """(d,) mean E_img over all goal images, in eval mode: the stored half of the goal prototype.

    A FiLM-conditioned model encodes each goal image under `goal_ids` (G, L), an instruction
    naming its own centred target.
    """
    model.eval()
    if model.conditioned and goal_ids is None:
        raise ValueError("a FiLM-conditioned model needs each goal image's instruction (goal_ids)")
    dev = model.device
    parts = []
    for i in range(0, len(goal_images_u8), batch):
        text = model.encode_text(goal_ids[i : i + batch].to(dev)) if goal_ids is not None else None
        parts.append(model.encode_images(to_float(goal_images_u8[i : i + batch].to(dev)), text))
    return torch.cat(parts).mean(dim=0).cpu()


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
    dev = model.device
    goal = goal.to(dev)
    out = []
    for i in range(0, len(images_u8), batch):
        ids = tokenizer.batch(instructions[i : i + batch]).to(dev)
        out.append(model(to_float(images_u8[i : i + batch].to(dev)), ids, goal).cpu())
    return torch.cat(out)


def score(
    distances: torch.Tensor, data: ImageSet, setting: str, understood: Sequence[bool] | None = None
) -> EvalResult:
    """Compare argmin-distance actions with the truth labels; an image whose instruction the loop did
    not understand (`understood` False: refused or misread, as flown) counts as wrong on every axis.
    The confusion matrix is the model's own choices."""
    pred = distances.argmin(dim=1)
    true = data.labels
    ok = torch.ones_like(true, dtype=torch.bool) if understood is None else torch.tensor(list(understood))
    confusion = torch.zeros(NUM_ACTIONS, NUM_ACTIONS, dtype=torch.long)
    confusion.index_put_((true, pred), torch.ones_like(true), accumulate=True)
    correct = (pred == true) & ok
    return EvalResult(
        rank1=float(correct.float().mean()),
        x_accuracy=float(((pred // 3 == true // 3) & ok).float().mean()),
        z_accuracy=float(((pred % 3 == true % 3) & ok).float().mean()),
        confusion=confusion.tolist(),
        n=len(data),
        instructions=setting,
        predictions=pred.tolist(),
        labels=true.tolist(),
        offsets_px=data.offsets.tolist(),
        ids=list(data.ids),
        correct=correct.tolist(),
    )


def pair_described(
    targets: Sequence[tuple[TargetRef, ...]],
    templates: Sequence[str],
    corpus: str,
    seed: int,
    vocabulary: Vocabulary | None = None,
) -> list[str]:
    """One instruction per image asking for its named target by a synonym of `corpus` (of `vocabulary`),
    with its colour where another target of its kind is in view (seeded)."""
    rng = np.random.default_rng(seed)
    return [describe(named_target_name(refs, False), templates, corpus, rng, vocabulary) for refs in targets]


def pair_kind_phrases(
    kinds: Sequence[str], phrases: dict[str, list[str]], seed: int, path: str = "the instruction file"
) -> list[str]:
    """One phrase per image from a `kind: phrase` file, written for its named target's kind (seeded)."""
    missing = sorted(set(kinds) - set(phrases))
    if missing:
        raise InstructionError(
            f"{path} has no phrase for kind {', '.join(map(repr, missing))}, which the test images name "
            f"(it has {', '.join(phrases)}): add a line '{missing[0]}: <phrase>'"
        )
    rng = np.random.default_rng(seed)
    return [fill(phrases[k][int(rng.integers(len(phrases[k])))], k) for k in kinds]


def instructions_for(ckpt: LoadedCheckpoint, data: ImageSet, setting: str, seed: int) -> list[str]:
    """Each image's instruction under `setting` ("train", "heldout", a template file or a
    `kind: phrase` file). A checkpoint trained on described targets hears its targets by
    the setting's synonyms (held-out synonyms with held-out templates); one trained the
    paper's way hears each kind's plain name, as it was trained and as its numbers were taken."""
    train_meta = ckpt.meta.get("train", {})
    trained_with = str(train_meta.get("instructions", "varied"))
    if setting not in ("train", "heldout") and is_operator_words_file(setting):
        if not data.targets:
            raise InstructionError(f"{setting}: operator words need a dataset that lists its targets")
        return pair_operator_words(data.targets, load_operator_words(setting), seed)
    if setting not in ("train", "heldout") and is_kind_phrase_file(Path(setting)):
        return pair_kind_phrases(data.kinds, read_kind_phrases(Path(setting)), seed, setting)
    templates = instruction_templates(setting, trained_with)
    if train_meta.get("target_choice", "named") == "described" and data.targets:
        corpus = "heldout" if setting == "heldout" else ("fixed" if trained_with == "fixed" else "train")
        return pair_described(data.targets, templates, corpus, seed, checkpoint_vocabulary(ckpt))
    return pair_instructions(data.kinds, templates, seed)


def checkpoint_vocabulary(ckpt: LoadedCheckpoint) -> Vocabulary:
    """The shipped vocabulary with the kinds the checkpoint was trained on beyond it (a fine-tune's)."""
    return vocabulary_with(words_only(ckpt.meta.get("kinds") or {}))


def _rank1_by(result: EvalResult, keys: Sequence[str]) -> dict[str, dict[str, float]]:
    groups: dict[str, list[bool]] = {}
    for correct, key in zip(result.correct, keys, strict=True):
        groups.setdefault(key, []).append(correct)
    return {k: {"n": len(v), "rank1": sum(v) / len(v)} for k, v in sorted(groups.items())}


def _group_rank1(result: EvalResult, data: ImageSet) -> None:
    """Fill `result`'s rank-1 by targets in view, and by named kind and targets in view."""
    in_view = [str(sum(t.in_view for t in refs)) for refs in data.targets]
    result.by_targets_in_view = _rank1_by(result, in_view)
    kinds = [f"{kind}/{k}" for kind, k in zip(data.kinds, in_view, strict=True)]
    result.by_kind_and_targets = _rank1_by(result, kinds)


def asker(ckpt: LoadedCheckpoint, setting: str) -> Ask:
    """How `setting` asks for a target it makes up (absent targets, empty images): in its own words."""
    if setting not in ("train", "heldout") and is_operator_words_file(setting):
        return load_operator_words(setting).instruction
    trained_with = str(ckpt.meta.get("train", {}).get("instructions", "varied"))
    corpus = "heldout" if setting == "heldout" else ("fixed" if trained_with == "fixed" else "train")
    if setting not in ("train", "heldout") and is_kind_phrase_file(Path(setting)):
        templates, corpus = builtin_templates("heldout"), "heldout"
    else:
        templates = instruction_templates(setting, trained_with)
    vocabulary = checkpoint_vocabulary(ckpt)
    return lambda name, rng: describe(name, templates, corpus, rng, vocabulary)


def evaluate_loaded(
    ckpt: LoadedCheckpoint,
    data: ImageSet,
    setting: str = "train",
    seed: int = 0,
    instructions: Sequence[str] | None = None,
    mirror_tta: bool = False,
) -> EvalResult:
    """Rank-1 of `ckpt` on `data`; `instructions` (one per image) default to `instructions_for(setting)`.

    `mirror_tta`: score each image as the sum of its own distances and its left-right mirror image's,
    the mirror's actions swapped back (test-time augmentation; the planner does the same where its
    checkpoint's `planner.mirror_tta` says so).
    """
    if instructions is None:
        instructions = instructions_for(ckpt, data, setting, seed)
    dist = predict_distances(ckpt.model, ckpt.tokenizer, ckpt.goal_image_embedding, data.images, instructions)
    if mirror_tta:
        dist = with_mirror(dist, _mirror_image_distances(ckpt, data, instructions))
    return score(dist, data, setting + ("+mirror" if mirror_tta else ""))


def _mirror_image_distances(
    ckpt: LoadedCheckpoint, data: ImageSet, instructions: Sequence[str]
) -> torch.Tensor:
    """(N, 9) distances of every image's left-right mirror image, in the mirror image's action order."""
    mirrored = data.images.flip(-1).contiguous()
    return predict_distances(ckpt.model, ckpt.tokenizer, ckpt.goal_image_embedding, mirrored, instructions)


def evaluate_checkpoint(
    model_dir: Path,
    data_dir: Path,
    setting: str = "train",
    split: str = "test",
    epsilon_px: float | None = None,
    seed: int = 0,
    mirror_tta: bool = False,
) -> EvalResult:
    """Load a checkpoint and a dataset split, and evaluate (ε defaults to the dataset's)."""
    return evaluate_checkpoint_modes(model_dir, data_dir, setting, split, epsilon_px, seed, (mirror_tta,))[0]


def evaluate_checkpoint_modes(
    model_dir: Path,
    data_dir: Path,
    setting: str = "train",
    split: str = "test",
    epsilon_px: float | None = None,
    seed: int = 0,
    mirror_modes: Sequence[bool] = (False,),
    flown: bool = False,
) -> list[EvalResult]:
    """`evaluate_checkpoint` once per mirror mode, loading and encoding only once; `flown`: then the
    same instructions as flown (`operator_words.as_flown`), once per mirror mode again. Presence is
    judged per result: on each image alone, or as the mean with its mirror image's as the planner does."""
    ckpt = load_checkpoint(model_dir)
    index = load_index(data_dir)
    eps = index.default_epsilon_px() if epsilon_px is None else epsilon_px
    data = load_images(index.split(split), ckpt.config.image_size, eps, desc=split)
    instructions = instructions_for(ckpt, data, setting, seed)
    empty = None
    if ckpt.model.presence is not None and data.targets and split == "test" and index.split("empty"):
        empty = load_images(index.split("empty"), ckpt.config.image_size, eps, "empty", in_view_only=False)
    readings: list[tuple[str, Sequence[str], Ask, Flown | None]] = [
        (setting, instructions, asker(ckpt, setting), None)
    ]
    if flown:
        reading = as_flown(instructions, data.targets)
        readings.append((f"{setting} as flown", reading.heard, flown_asker, reading))
    threshold = presence_threshold(ckpt.planner)
    by_kind: dict[bool, dict[str, float | int]] = {}
    if ckpt.model.presence is not None and data.targets:
        for mirror in mirror_modes:  # the words do not depend on the reading: once per mirror mode
            by_kind[mirror] = judge_presence(
                *kind_presence_pairs(ckpt, data, empty, mirror), threshold
            ).summary()
    results = []
    for name, texts, ask, reading in readings:
        dist = predict_distances(ckpt.model, ckpt.tokenizer, ckpt.goal_image_embedding, data.images, texts)
        mirrored = _mirror_image_distances(ckpt, data, texts) if any(mirror_modes) else None
        understood = None if reading is None else [v == UNDERSTOOD for v in reading.verdicts]
        for mirror in mirror_modes:
            result = score(
                with_mirror(dist, mirrored) if mirror else dist, data, name + ("+mirror" if mirror else ""),
                understood,
            )  # fmt: skip
            _group_rank1(result, data)
            result.parsed = None if reading is None else reading.counts()
            if ckpt.model.presence is not None and data.targets:
                pairs = presence_pairs(ckpt, data, texts, empty, ask, seed, mirror)
                result.presence = judge_presence(*pairs, threshold).summary()
                result.presence_by_kind = by_kind[mirror]
            log.info("%s on %s/%s (%d images, %s): rank-1 %.4f", model_dir, data_dir, split, result.n,
                     result.instructions, result.rank1)  # fmt: skip
            results.append(result)
    return results
