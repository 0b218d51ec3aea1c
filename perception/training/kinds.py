"""Which kinds a detector run trains on, and the network it starts from.

From scratch: the shipped kinds and every other kind the training rows hold. Fine-tuning (`--init`): the
starting checkpoint's kinds, and a heatmap channel more for each kind the rows hold that it lacks
(`detector_model.grow_kinds`): the head grows, the kinds it knows keep their weights. The words of the
kinds beyond the shipped ones come from where they were declared (the datasets' `dataset.json`, the
starting checkpoint) and are saved with the new checkpoint (`config.json`'s `kinds`), so that missions,
the instruction parser and the planner know the kind by the detector that finds it. A kind two sources
give different words is refused (`own_kinds.KindConflictError`) before anything trains.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from drone_inspect_core.dataset import load_manifest
from drone_inspect_core.own_kinds import checkpoint_kinds, dataset_kinds, merge_kinds, own_kinds_of
from drone_inspect_core.vocabulary import kind_mapping, parse_kind
from perception.detector_model import CentreNet, DetectorConfig, grow_kinds
from perception.errors import DetectorCheckpointError
from perception.image_detector import load_model
from perception.training.data import is_positive

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class StartingPoint:
    model: CentreNet
    own_kinds: dict[str, dict[str, Any]]
    """The words of the model's kinds beyond the shipped ones (saved with the checkpoint)."""
    added: tuple[str, ...]
    """Kinds the training data adds to the starting checkpoint's (empty from scratch)."""
    missing: tuple[str, ...]
    """Kinds the model knows that no training row shows (a fine-tune may forget them)."""


def row_kinds(data_dirs: list[Path]) -> tuple[str, ...]:
    """The kinds of the targets the datasets' rows show, in order of first appearance."""
    kinds: dict[str, None] = {}
    for folder in data_dirs:
        rows, _ = load_manifest(folder, check_images=False)
        kinds.update((row["target_kind"], None) for row in rows if is_positive(row))
    return tuple(kinds)


def starting_point(
    data_dirs: list[Path], init_dir: Path | None, detector: DetectorConfig | None
) -> StartingPoint:
    """The network to train (the init's, grown; or a new one) and the words of its own kinds.

    `detector` is the architecture asked for: from scratch it is used (kinds extended by the data's);
    with `init_dir` its input size must be the checkpoint's (the rest is the checkpoint's)."""
    start = load_model(init_dir) if init_dir is not None else None  # a bad checkpoint is said first
    if start is not None and detector is not None and detector.input_size != start.config.input_size:
        raise DetectorCheckpointError(
            init_dir, f"its input size is {start.config.input_size} px, not {detector.input_size}"
        )
    sources: list[tuple[str, dict[str, Any]]] = []
    if init_dir is not None:
        sources.append((f"--init {init_dir}", checkpoint_kinds(init_dir)))
    for folder in data_dirs:
        sources.append((f"dataset {folder}", dataset_kinds(load_manifest(folder, check_images=False)[1])))
    declared = merge_kinds(sources)
    seen = row_kinds(data_dirs)
    base = start.config.kinds if start is not None else (detector or DetectorConfig()).kinds
    added = tuple(k for k in seen if k not in base)
    for name in added:
        if name not in declared:
            log.warning("no words recorded for the kind %r: it is known by its name alone", name)
            declared[name] = kind_mapping(parse_kind(name, {}))
    if start is not None:
        model = grow_kinds(start, (*base, *added))
        if added:
            log.info("the head grows: %s join %s", ", ".join(added), ", ".join(base))
    else:
        model = CentreNet(replace(detector or DetectorConfig(), kinds=(*base, *added)))
    missing = tuple(k for k in model.config.kinds if k not in seen)
    return StartingPoint(model, own_kinds_of(model.config.kinds, declared), added, missing)
