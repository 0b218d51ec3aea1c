"""Fine-tuning the planner from a checkpoint: `dronectl train --init DIR`, or the `own-target` preset (the
shipped checkpoint).

The checkpoint's model and tokenizer are the start: its image encoder is trained, so a few epochs on a
flown collection of one's own target (with a dataset of the kinds it already knows beside it, so that it
keeps them) teach it the new kind. The new kind's words reach the text side: the tokenizer gains every
word of the training text it lacks as a token of its own (the known tokens keep their ids), and the text
encoder's embedding table a row for each, started at the mean of the rows of the pieces the checkpoint
spelt that word with (so the fine-tune starts from what the checkpoint heard).

The words themselves come from where the kind was declared: the datasets' `dataset.json` (`kinds`, as the
collection recorded them) and the starting checkpoint's; a kind given two sets of words is refused
(`own_kinds.KindConflictError`). They are saved with the new checkpoint (`config.json`'s `kinds`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import torch

from controller.planning.latent.checkpoint import load_checkpoint
from controller.planning.latent.config import ModelConfig
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.tokenizer import InstructionTokenizer
from drone_inspect_core.dataset import load_manifest
from drone_inspect_core.own_kinds import checkpoint_kinds, dataset_kinds, merge_kinds
from drone_inspect_core.vocabulary import Vocabulary, vocabulary_with

log = logging.getLogger(__name__)
EMBEDDING = "text_encoder.embed.weight"


@dataclass(frozen=True)
class TrainingWords:
    vocabulary: Vocabulary
    """The shipped vocabulary with the kinds the datasets and the starting checkpoint add."""
    own_kinds: dict[str, dict[str, Any]]
    """Those added kinds' words (saved with the checkpoint)."""


def training_words(data_dirs: Sequence[Path], init_dir: Path | None) -> TrainingWords:
    """The kinds a planner run trains on beyond the shipped ones, and their words."""
    sources: list[tuple[str, dict[str, Any]]] = []
    if init_dir is not None:
        sources.append((f"--init {init_dir}", checkpoint_kinds(init_dir)))
    for folder in data_dirs:
        sources.append((f"dataset {folder}", dataset_kinds(load_manifest(folder, check_images=False)[1])))
    own = merge_kinds(sources)
    return TrainingWords(vocabulary_with(own), own)


@dataclass(frozen=True)
class FineTuneStart:
    model: LatentDynamicsModel
    tokenizer: InstructionTokenizer
    config: ModelConfig
    new_tokens: tuple[str, ...]


def check_start(init_dir: Path) -> ModelConfig:
    """The starting checkpoint's model config; `PlannerCheckpointError` naming the file when it is not a
    planner checkpoint (said before any data loads)."""
    return load_checkpoint(init_dir).config


def start_from(init_dir: Path, corpus: Sequence[str]) -> FineTuneStart:
    """The checkpoint's model and tokenizer, grown by the words of `corpus` the tokenizer lacks."""
    ckpt = load_checkpoint(init_dir)
    tokenizer = ckpt.tokenizer.with_words(corpus)
    config = replace(ckpt.config, vocab_size=tokenizer.vocab_size)
    state = {k: v.clone() for k, v in ckpt.model.state_dict().items()}
    old = state[EMBEDDING]  # (V, d)
    new_ids = range(old.shape[0], tokenizer.vocab_size)
    rows = [old[ckpt.tokenizer.pieces(tokenizer.token(i)) or [0]].mean(dim=0) for i in new_ids]
    if rows:
        state[EMBEDDING] = torch.cat([old, torch.stack(rows)])
    model = LatentDynamicsModel(config)
    model.load_state_dict(state, strict=True)
    new_tokens = tuple(tokenizer.token(i) for i in new_ids)
    if new_tokens:
        log.info("the text side learns %d new words: %s", len(new_tokens), ", ".join(new_tokens))
    return FineTuneStart(model, tokenizer, config, new_tokens)
