"""The planner's rank-1 on dataset images as the centring loop shows them to it, the detector included.

`evaluate`'s rank-1 scores the planner alone: the image as it is, the instruction in the planner's
words. The loop does more before the planner sees a frame: the detector finds the targets, the loop
takes the detection the instruction asks for (its kind; among twins, the trim colour the detector
reads), and paints over the other targets of that kind (`CentringLoop._planner_picture`), so that the
planner plans towards the one the loop tests ε on. Here each test image whose named target is in view
goes through the same steps:

1. the loop's query for the named target: its kind, and its trim colour where the scene has another
   target of that kind (twins: an operator must name the colour; elsewhere the kind is enough);
2. the detector's detections (`perception.detector.detect_all`) and the one the loop takes
   (`grounding.select_target`);
3. the other detections of its kind painted over (`perception.masking.paint_over_twins`, as the loop);
4. the planner asked in its trained words (`grounding.planner_instruction`) through the adapter the loop
   uses (`LatentPlannerAdapter`, mirror test-time augmentation as its checkpoint says).

Counted over every such image: rank-1 (the planner's action is the named target's label), the images
where no detection matches the query (the loop would hold and look again: no move, a miss here), and
those where the detection taken is nearer another target's true centre than the named one's (the
detector's colour reading chose the wrong twin); and rank-1 over the images where a detection matched.

"Not in view" as the loop decides it on one read: a target is taken only when a detection matches the
query and the planner's presence head, asked by kind on the picture it would see, does not say the kind
is out of view. Counted for each named target (called absent: missed) and for each kind no target in
view has (called present: the loop would fly towards something). The result keeps each of these pairs'
p(in view) as the loop asks it (None where no detection matches: absent whatever the threshold), so the
same pairs on validation scenes choose the threshold (`presence_calibration`).

`through_stream`: each image first goes through the simulated vehicle's MJPEG stream as a stream camera
receives it (`perception.evaluation.streamed.as_streamed`: 4:2:0 JPEG), and the detector and the planner
both see that picture, as in a flight through `sim-mavlink` or an autopilot's SITL.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from controller.planning.actions import label_from_offset
from controller.planning.grounding import TargetQuery, planner_instruction, presence_query, select_target
from controller.planning.planners import LatentPlannerAdapter, Observation, Plan
from controller.training.data import Row, load_index
from drone_inspect_core.dataset import read_image_rgb
from perception.detector import Detector, detect_all
from perception.evaluation.streamed import as_streamed
from perception.masking import paint_over_twins
from perception.types import Detection


@dataclass(frozen=True)
class WithDetectorResult:
    """Rank-1 of the planner as the loop shows it each image; the misses the detector caused."""

    n: int
    rank1: float
    not_found: int
    """Images where no detection matched the query: the loop would not move."""
    wrong_choice: int
    """Images where the detection taken is another target (nearer its true centre)."""
    twins: int
    """Images whose query names a colour (the scene has another target of the named one's kind)."""
    twins_rank1: float | None
    matched_rank1: float | None
    """Rank-1 over the images where a detection matched: the planner's part alone."""
    present_called_absent: float | None = None
    """"Not in view" as the loop decides it (a matching detection, and the planner's presence head not
    saying its kind is out of view): the share of named targets (in view) it would call absent; None
    when the planner gives no verdict."""
    absent_called_present: float | None = None
    """The same decision asked for each kind no target in view has: the share it would call present."""
    absent_pairs: int = 0
    present_presence: tuple[float | None, ...] = field(default=(), repr=False)
    """Each named target's p(in view) as the loop asks it; None where no detection matches."""
    absent_presence: tuple[float | None, ...] = field(default=(), repr=False)
    """The same for each kind no target in view has (the pairs of `absent_called_present`)."""
    through_stream: bool = False
    """The images went through the simulated stream's JPEG first (the module docstring)."""

    def as_dict(self) -> dict[str, float | int | None]:
        """The figures (the per-pair p's left out)."""
        body = asdict(self)
        del body["present_presence"], body["absent_presence"]
        return body


def called_absent(p: float | None, threshold: float) -> bool:
    """The loop's verdict on one read of a pair: absent where no detection matches (`p` None) or the
    planner's p(in view) lies below `threshold`."""
    return p is None or p < threshold


def loop_rates(
    present: Sequence[float | None], absent: Sequence[float | None], threshold: float
) -> tuple[float, float]:
    """(present pairs called absent, absent pairs called present), as shares, at `threshold`."""
    missed = sum(called_absent(p, threshold) for p in present)
    taken = sum(not called_absent(p, threshold) for p in absent)
    return missed / max(1, len(present)), taken / max(1, len(absent))


def loop_query(row: Row) -> TargetQuery:
    """What an operator asks for the named target: its kind, and its colour where the scene has twins."""
    named, others = row.targets[0], row.targets[1:]
    twins = any(t.kind == named.kind for t in others)
    return TargetQuery(named.kind, named.attribute if twins else None)


def _took_another(detection: Detection, row: Row, width: int, height: int) -> bool:
    """Whether `detection` lies nearer another in-view target's true centre than the named one's."""

    def gap(offset: tuple[float, float]) -> float:
        return math.dist(detection.centre_px, (offset[0] + width / 2.0, offset[1] + height / 2.0))

    named = gap(row.targets[0].offset_px)
    return any(t.in_view and gap(t.offset_px) < named for t in row.targets[1:])


def evaluate_with_detector(
    model_dir: Path,
    data_dir: Path,
    detector: Detector,
    split: str = "test",
    epsilon_px: float | None = None,
    through_stream: bool = False,
) -> WithDetectorResult:
    """Score the checkpoint at `model_dir` on `data_dir`'s `split` as the loop shows it each image (see
    the module docstring); `epsilon_px` None: the dataset's default ε; `through_stream`: each image as
    the simulated stream delivers it."""
    index = load_index(data_dir)
    eps = epsilon_px if epsilon_px is not None else index.default_epsilon_px()
    planner = LatentPlannerAdapter(model_dir)
    rows = [r for r in index.split(split) if r.in_view and r.targets]
    if not rows:
        raise ValueError(f"{data_dir}: no {split} image whose named target is in view")
    hits = not_found = wrong = twins = twin_hits = 0
    present: list[float | None] = []
    absent: list[float | None] = []
    kinds = sorted({t.kind for r in rows for t in r.targets})
    for row in rows:
        image = read_image_rgb(row.image)  # the folder's path joined already, relative or not
        if through_stream:
            image = as_streamed(image)
        height, width = image.shape[:2]
        query = loop_query(row)
        detections = detect_all(detector, image)
        for kind in kinds:  # asked for a kind not in view: what the loop would take for it
            if not any(t.in_view and t.kind == kind for t in row.targets):
                absent.append(_presence(planner, image, detections, TargetQuery(kind), eps))
        chosen = select_target(detections, query)
        named_twins = query.attribute is not None
        twins += named_twins
        if chosen is None:
            not_found += 1
            present.append(None)
            continue
        wrong += _took_another(chosen, row, width, height)
        picture = paint_over_twins(image, chosen, detections)
        words = planner_instruction(query)
        plan = planner.plan(Observation(picture, chosen, words, eps, None, detections))
        present.append(_asked_presence(planner, picture, chosen, detections, query, eps, (words, plan)))
        hit = plan.action.index == label_from_offset(row.offset_px[0], row.offset_px[1], eps).index
        hits += hit
        twin_hits += hit and named_twins
    threshold = planner.presence_threshold
    rates = None if threshold is None else loop_rates(present, absent, threshold)
    return WithDetectorResult(
        n=len(rows),
        rank1=hits / len(rows),
        not_found=not_found,
        wrong_choice=wrong,
        twins=twins,
        twins_rank1=twin_hits / twins if twins else None,
        matched_rank1=hits / (len(rows) - not_found) if len(rows) > not_found else None,
        present_called_absent=None if rates is None else rates[0],
        absent_called_present=None if rates is None or not absent else rates[1],
        absent_pairs=len(absent),
        present_presence=tuple(present),
        absent_presence=tuple(absent),
        through_stream=through_stream,
    )


def _presence(
    planner: LatentPlannerAdapter,
    image: np.ndarray,
    detections: tuple[Detection, ...],
    query: TargetQuery,
    eps: float,
) -> float | None:
    """p(in view) of `query`'s target as the loop asks it on this read (`_asked_presence`); None where no
    detection matches it."""
    chosen = select_target(detections, query)
    if chosen is None:
        return None
    picture = paint_over_twins(image, chosen, detections)
    return _asked_presence(planner, picture, chosen, detections, query, eps)


def _asked_presence(
    planner: LatentPlannerAdapter,
    picture: np.ndarray,
    chosen: Detection,
    detections: tuple[Detection, ...],
    query: TargetQuery,
    eps: float,
    asked: tuple[str, Plan] | None = None,
) -> float | None:
    """The planner's p(in view), asked by kind on the picture it sees (`CentringLoop._confirm`); None
    from a planner without a presence head. `asked`: words the planner was already asked on this
    picture, and its plan (used again when they are the kind's words)."""
    words = planner_instruction(presence_query(query, chosen))
    if asked is not None and asked[0] == words:
        plan = asked[1]
    else:
        plan = planner.plan(Observation(picture, chosen, words, eps, None, detections))
    return plan.presence
