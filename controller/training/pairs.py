"""Training pairs of the `described` target choice: which target each sample asks for, and in which words.

A multi-target image holds a lesson per target: "centre the valve" and "centre the gauge"
ask for different moves from the same pixels, so the model must read the instruction to
rank the actions (the paper's model, given one target per image, may ignore it). Per
sample this draws:

- a target in view (the image's named target half of the time, else any target in view),
  named by a training synonym of its kind, with its trim colour when another target of
  the same kind is in view (else a third of the time): the label is that target's move;
- or, for `absent_fraction` of the samples, a kind or kind-and-colour that no target of
  the scene has: a negative state, which trains only the presence head.

Every instruction the sampler can produce is tokenised once, up front.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from controller.planning.grounding import TargetQuery
from controller.planning.latent.tokenizer import InstructionTokenizer
from controller.training.data import TargetRef
from controller.training.phrasing import COLOURS, phrasing_table, synonyms
from drone_inspect_core.vocabulary import Vocabulary, shipped_vocabulary

NAMED_FRACTION = 0.5
"""Share of present samples that ask for the image's named target (the rest: any target in view)."""
ATTRIBUTE_FRACTION = 1 / 3
"""Share of unambiguous samples that still say the target's colour (so colour words are learned)."""


@dataclass(frozen=True)
class SampledPairs:
    ids: torch.Tensor
    """(B, L) token ids of each sample's instruction."""
    offsets_px: torch.Tensor
    """(B, 2) pixel offset of the asked-for target (zeros for absent samples)."""
    present: torch.Tensor
    """(B,) bool: the asked-for target is in view."""
    teacher_ids: torch.Tensor | None = None
    """(B, L') the same instructions in a distillation teacher's tokens (`controller.training.distill`);
    None without a teacher."""


def target_name_for(target: TargetRef, visible: Sequence[TargetRef], with_colour: bool) -> TargetQuery:
    """How to ask for `target` among the targets in view: its kind, and its colour where needed or wanted."""
    twins = sum(1 for t in visible if t.kind == target.kind) > 1
    colour = target.attribute if (twins or with_colour) else None
    return TargetQuery(target.kind, colour)


def named_target_name(refs: Sequence[TargetRef], with_colour: bool) -> TargetQuery:
    """How to ask for an image's named target (`refs[0]`) among the targets it shows."""
    visible = [t for t in refs if t.in_view] or [refs[0]]
    return target_name_for(refs[0], visible, with_colour)


def absent_names(targets: Sequence[TargetRef], vocabulary: Vocabulary | None = None) -> list[TargetQuery]:
    """Names that match no target of the scene: a kind none has (of `vocabulary`'s, default the shipped
    ones), or a kind with a colour none of it has."""
    kinds = {t.kind for t in targets}
    names = [TargetQuery(k) for k in (vocabulary or shipped_vocabulary()).kind_names if k not in kinds]
    for kind in sorted(kinds):
        colours = {t.attribute for t in targets if t.kind == kind}
        if None in colours:
            continue  # a target of unknown colour could be any colour
        names += [TargetQuery(kind, c) for c in COLOURS if c not in colours]
    return names


class DescriptionSampler:
    """Per-sample target choice and instruction, from pre-tokenised (template, synonym, colour) phrases."""

    def __init__(
        self,
        tokenizer: InstructionTokenizer,
        templates: Sequence[str],
        corpus: str,
        absent_fraction: float,
        named_fraction: float = NAMED_FRACTION,
        vocabulary: Vocabulary | None = None,
        teacher_tokenizer: InstructionTokenizer | None = None,
    ) -> None:
        """`teacher_tokenizer`: a distillation teacher's, which spells every sample's instruction too."""
        self.vocabulary = vocabulary
        self.templates = list(templates)
        self.corpus = corpus
        self.absent_fraction = absent_fraction
        self.named_fraction = named_fraction
        table = phrasing_table(self.templates, corpus, vocabulary)
        keys, texts = [key for key, _ in table], [text for _, text in table]
        self.row_of = {key: i for i, key in enumerate(keys)}
        self.ids = tokenizer.batch(texts)  # (K, L)
        self.teacher_ids = None if teacher_tokenizer is None else teacher_tokenizer.batch(texts)

    def _ids_row(self, name: TargetQuery, rng: np.random.Generator) -> int:
        n_syn = len(synonyms(name.kind, self.corpus, self.vocabulary))
        key = (name.kind, name.attribute, int(rng.integers(n_syn)), int(rng.integers(len(self.templates))))
        return self.row_of[key]

    def named(self, targets: Sequence[tuple[TargetRef, ...]], rng: np.random.Generator) -> torch.Tensor:
        """(B, L) ids asking for each image's named target (goal images: "the named target is centred")."""
        rows = []
        for refs in targets:
            rows.append(self._ids_row(named_target_name(refs, rng.random() < ATTRIBUTE_FRACTION), rng))
        return self._trimmed(rows)

    def sample(self, targets: Sequence[tuple[TargetRef, ...]], rng: np.random.Generator) -> SampledPairs:
        rows, offsets, present = [], [], []
        for refs in targets:
            visible = [t for t in refs if t.in_view and np.isfinite(t.offset_px).all()]
            absent = absent_names(refs, self.vocabulary)
            if absent and (not visible or rng.random() < self.absent_fraction):
                rows.append(self._ids_row(absent[int(rng.integers(len(absent)))], rng))
                offsets.append((0.0, 0.0))
                present.append(False)
                continue
            if not visible:
                raise ValueError("a training image with no target in view and nothing absent to ask for")
            if refs[0] in visible and rng.random() < self.named_fraction:
                target = refs[0]
            else:
                target = visible[int(rng.integers(len(visible)))]
            name = target_name_for(target, visible, rng.random() < ATTRIBUTE_FRACTION)
            rows.append(self._ids_row(name, rng))
            offsets.append(target.offset_px)
            present.append(True)
        return SampledPairs(
            self._trimmed(rows),
            torch.tensor(offsets, dtype=torch.float32),
            torch.tensor(present, dtype=torch.bool),
            None if self.teacher_ids is None else self._trimmed(rows, self.teacher_ids),
        )

    def _trimmed(self, rows: list[int], table: torch.Tensor | None = None) -> torch.Tensor:
        ids = (self.ids if table is None else table)[torch.tensor(rows, dtype=torch.long)]
        return ids[:, : int(ids.ne(0).sum(dim=1).max())]
