"""Negative states: how sure the planner is that the target it was asked for is not in view.

A checkpoint with a presence head gives p(asked-for target in view) from z_s. It is judged
on pairs whose truth is known from the manifest:

- present: each test image asked for its named target (the same pairs as rank-1);
- absent: each test image asked for something its scene does not hold (a kind none of its
  targets has, or a kind with a colour none of that kind has), and each `empty` image (no
  target in view) asked for its scene's named target.

As the loop asks (`kind_presence_pairs`): before it takes a detection for the target it asks the
planner whether that kind is in view (`grounding.presence_query`), so these pairs ask by the kind
alone: present, each test image for its named target's kind; absent, each test image for every kind
none of its targets has, and each `empty` image for its named target's kind. The calibrated
threshold is chosen on such pairs of validation scenes (`presence_calibration`).

Reported: the area under the ROC curve (the chance that an absent pair scores lower than a
present one), and at the checkpoint's threshold (its config.json `planner.presence_threshold`,
chosen on validation scenes by `dronectl calibrate-presence`: `presence_calibration`; 0.5 where it
has none) the accuracy, the
share of present pairs called absent (a mission that would give up on a target in view) and of
absent pairs called present.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np
import torch

from controller.planning.grounding import TargetQuery, planner_instruction, presence_query
from controller.planning.latent.checkpoint import LoadedCheckpoint, PlannerSettings
from controller.training.data import ImageSet, to_float
from controller.training.pairs import absent_names, named_target_name
from drone_inspect_core.vocabulary import shipped_vocabulary

DEFAULT_THRESHOLD = 0.5
"""p(in view) below which a checkpoint without a calibrated threshold calls the target absent."""


@dataclass(frozen=True)
class PresenceResult:
    n_present: int
    n_absent: int
    auroc: float
    accuracy: float
    false_absent_rate: float
    """Present pairs with p below the threshold: the target was in view and the model said it was not."""
    false_present_rate: float
    mean_absent_confidence: float
    """Mean 1 − p over the absent pairs."""
    threshold: float = DEFAULT_THRESHOLD
    """p below this calls the target absent (the rates above are at it)."""

    def summary(self) -> dict[str, float | int]:
        return asdict(self)


Ask = Callable[[TargetQuery, np.random.Generator], str]
"""How an evaluation asks for a target in words: a name and a seeded generator → an instruction."""


def flown_asker(name: TargetQuery, rng: np.random.Generator) -> str:
    """What the planner hears in flight for a target asked for as `name`, whatever the words."""
    return planner_instruction(name)


@torch.inference_mode()
def presence_probabilities(
    ckpt: LoadedCheckpoint,
    images_u8: torch.Tensor,
    instructions: Sequence[str],
    batch: int = 128,
    mirror: bool = False,
) -> np.ndarray:
    """(N,) p(asked-for target in view) for N images, each with its own instruction; `mirror`: the mean
    with the left-right mirror image's, as the planner gives it with mirror test-time augmentation."""
    model = ckpt.model.eval()
    out = []
    for i in range(0, len(images_u8), batch):
        text = model.encode_text(ckpt.tokenizer.batch(instructions[i : i + batch]))
        x = to_float(images_u8[i : i + batch])
        views = (x, x.flip(-1)) if mirror else (x,)
        z_s = [model.fuse_state(model.encode_images(v, text), text) for v in views]
        out.append(torch.stack([torch.sigmoid(model.presence_logits(z)) for z in z_s]).mean(dim=0))
    return torch.cat(out).numpy().astype(np.float64)


def absent_instructions(data: ImageSet, ask: Ask, seed: int) -> list[str]:
    """One instruction per image asking for something its scene does not hold (seeded)."""
    rng = np.random.default_rng(seed)
    out = []
    for refs in data.targets:
        names = absent_names(refs)
        out.append(ask(names[int(rng.integers(len(names)))], rng))
    return out


def empty_instructions(data: ImageSet, ask: Ask, seed: int) -> list[str]:
    """One instruction per image asking for its scene's named target (which is out of view)."""
    rng = np.random.default_rng(seed)
    return [ask(named_target_name(refs, False), rng) for refs in data.targets]


def presence_pairs(
    ckpt: LoadedCheckpoint,
    data: ImageSet,
    present: Sequence[str],
    empty: ImageSet | None,
    ask: Ask,
    seed: int,
    mirror: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """p(in view) of the present pairs (`data` asked in `present`) and of the absent ones: each image of
    `data` asked for something its scene lacks, each `empty` image for its scene's named target."""
    p_present = presence_probabilities(ckpt, data.images, present, mirror=mirror)
    absent = [
        presence_probabilities(ckpt, data.images, absent_instructions(data, ask, seed + 1), mirror=mirror)
    ]
    if empty is not None and len(empty):
        texts = empty_instructions(empty, ask, seed)
        absent.append(presence_probabilities(ckpt, empty.images, texts, mirror=mirror))
    return p_present, np.concatenate(absent)


def kind_presence_pairs(
    ckpt: LoadedCheckpoint, data: ImageSet, empty: ImageSet | None, mirror: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """p(in view) asked as the loop asks before it takes a detection for the target
    (`grounding.presence_query`: by the kind alone, in the planner's words), for the present pairs (each
    image of `data` asked for its named target's kind) and the absent ones (each image asked for every
    kind none of its targets has; each `empty` image for its named target's kind). No draw: every pair."""

    def words(kind: str) -> str:
        return planner_instruction(presence_query(TargetQuery(kind)))

    p_present = presence_probabilities(
        ckpt, data.images, [words(refs[0].kind) for refs in data.targets], mirror=mirror
    )
    index, texts = [], []
    for i, refs in enumerate(data.targets):
        have = {t.kind for t in refs}
        missing = [k for k in shipped_vocabulary().kind_names if k not in have]
        index += [i] * len(missing)
        texts += [words(k) for k in missing]
    absent = [presence_probabilities(ckpt, data.images[index], texts, mirror=mirror)] if texts else []
    if empty is not None and len(empty):
        absent.append(
            presence_probabilities(
                ckpt, empty.images, [words(refs[0].kind) for refs in empty.targets], mirror=mirror
            )
        )
    return p_present, np.concatenate(absent) if absent else np.zeros(0)


def presence_threshold(settings: PlannerSettings) -> float:
    """The checkpoint's calibrated presence threshold (config.json `planner.presence_threshold`), else 0.5."""
    value = settings.presence_threshold
    return DEFAULT_THRESHOLD if value is None else value


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


def judge_presence(
    p_present: np.ndarray, p_absent: np.ndarray, threshold: float = DEFAULT_THRESHOLD
) -> PresenceResult:
    """The rates at `threshold`: p below it calls the target absent."""
    correct = int((p_present >= threshold).sum() + (p_absent < threshold).sum())
    n = len(p_present) + len(p_absent)
    return PresenceResult(
        n_present=len(p_present),
        n_absent=len(p_absent),
        auroc=auroc(p_present, p_absent),
        accuracy=correct / max(1, n),
        false_absent_rate=float((p_present < threshold).mean()) if len(p_present) else float("nan"),
        false_present_rate=float((p_absent >= threshold).mean()) if len(p_absent) else float("nan"),
        mean_absent_confidence=float((1.0 - p_absent).mean()) if len(p_absent) else float("nan"),
        threshold=threshold,
    )


def fewest_errors_threshold(present: Sequence[float | None], absent: Sequence[float | None]) -> float:
    """The threshold at which the loop's decision makes the fewest wrong calls on validation pairs: the
    share of present pairs called absent plus the share of absent pairs called present
    (`with_detector.called_absent`: a pair with `None`, no matching detection, is absent whatever the
    threshold). The error changes only at the pairs' scores; of the runs of thresholds that give the
    fewest, the widest, and its middle: as far from the present scores below it as from the absent
    ones above."""
    if len(present) == 0 or len(absent) == 0:
        raise ValueError("fewest_errors_threshold needs present and absent pairs")
    p = np.array([x for x in present if x is not None], dtype=np.float64)
    a = np.array([x for x in absent if x is not None], dtype=np.float64)
    edges = np.unique(np.concatenate([[0.0, 1.0], p, a]))  # the error is constant on (edges[i], edges[i+1]]
    lows, highs = edges[:-1], edges[1:]
    missed = (len(present) - len(p)) + (p[None, :] < highs[:, None]).sum(axis=1)  # threshold in (low, high]
    taken = (a[None, :] >= highs[:, None]).sum(axis=1)
    error = missed / len(present) + taken / len(absent)
    best = np.isclose(error, error.min(), rtol=0.0, atol=1e-12)
    run_start: float | None = None  # where the run of best intervals under way began
    widest = (0.0, 0.0)
    for low, high, ok in zip(lows, highs, best, strict=True):
        run_start = (low if run_start is None else run_start) if ok else None
        if run_start is not None and high - run_start > widest[1] - widest[0]:
            widest = (run_start, high)
    return float(sum(widest) / 2.0)
