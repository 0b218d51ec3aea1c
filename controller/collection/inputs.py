"""What a flown collection checks before anything connects: the kind and its words, the camera's
intrinsics, the goal box against the image, the goal file. Each problem is one `CollectionInputError`
line naming the option (`dronectl collect` exits 2; nothing is launched, no folder claimed).

The kind: a shipped one, one the simulated vehicle's `--scene` adds, or one a kinds file adds
(`--kinds FILE`: a `kinds:` section as a scene or mission file writes it; how a real vehicle's
collection names a target of one's own). A kind is given once: a kinds file that declares a kind the
scene or the shipped vocabulary already has is refused. The collected kind's words are recorded in
`dataset.json` (`kinds`), so the detector and the planner that train on the dataset learn them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from controller.collection.config import GOAL_HERE, GOAL_SCENE, FlownCollectConfig
from controller.collection.goal import GoalRecord, load_goal
from controller.collection.vehicles import SIM_CAMERA_OFFSET_FRD_M
from drone_inspect_core.own_kinds import load_kinds_file, own_kinds_of
from drone_inspect_core.vocabulary import (
    Vocabulary,
    VocabularyError,
    kind_mapping,
    parse_kinds,
    shipped_vocabulary,
)
from perception.camera_model import CameraModel, load_camera_file

SIM_IMAGE_PX, SIM_HFOV_DEG = 224, 60.0


class CollectionInputError(ValueError):
    """Bad input found before anything flies (a kind, a file, a folder); one line naming it."""


@dataclass(frozen=True)
class CheckedInputs:
    camera: CameraModel
    goal: GoalRecord | None
    """The goal file's record (`--goal FILE`), None for here / scene / --resume."""
    kinds: dict[str, dict[str, Any]]
    """The collected kind's words when it is not a shipped kind (`dataset.json`'s `kinds`), else {}."""


def camera_model_for(config: FlownCollectConfig) -> CameraModel:
    """The camera file's model, else the simulated camera's (a real vehicle needs a camera file)."""
    if config.camera_file is not None:
        return load_camera_file(config.camera_file)
    if config.simulated:
        return CameraModel.from_fov(
            SIM_IMAGE_PX, SIM_IMAGE_PX, SIM_HFOV_DEG, offset_frd_m=SIM_CAMERA_OFFSET_FRD_M
        )
    raise CollectionInputError(
        "--camera-file: a real vehicle's camera needs its intrinsics (a file with width, height and hfov_deg "
        "or a calibrated matrix; docs/own-target.md)"
    )


def collection_vocabulary(config: FlownCollectConfig) -> Vocabulary:
    """The shipped kinds, the simulated scene's own and the kinds file's (each kind given once)."""
    vocabulary = shipped_vocabulary()
    if config.simulated and config.sim.scene_file is not None:
        from sim_world.scene.config import load_scene_config  # a simulated world's kinds: its scene's too

        vocabulary = load_scene_config(config.sim.scene_file).vocabulary
    if config.kinds_file is None:
        return vocabulary
    try:
        added = load_kinds_file(config.kinds_file)
    except VocabularyError as exc:
        raise CollectionInputError(f"--kinds {exc}") from None
    for name in added:
        if name in vocabulary.kinds:
            where = "the shipped vocabulary" if name in shipped_vocabulary().kinds else "--scene"
            raise CollectionInputError(
                f"--kinds {config.kinds_file}: the kind {name!r} is given twice (also in {where}); "
                "declare it once"
            )
    try:
        return vocabulary.with_kinds(parse_kinds(added))
    except VocabularyError as exc:
        raise CollectionInputError(f"--kinds {config.kinds_file}: {exc}") from None


def check_inputs(config: FlownCollectConfig) -> CheckedInputs:
    """Everything that can be checked before connecting (see the module docstring)."""
    vocabulary = collection_vocabulary(config)
    try:
        kind = vocabulary.kind(config.kind)
    except VocabularyError as exc:
        raise CollectionInputError(f"--kind: {exc}") from None
    model = camera_model_for(config)
    if config.goal_box_px is not None:
        x, y, w, h = config.goal_box_px
        if x + w > model.width or y + h > model.height:
            raise CollectionInputError(
                f"--goal-box {x:g},{y:g},{w:g},{h:g} does not lie inside the camera's {model.width}x"
                f"{model.height} image (x + w <= {model.width}, y + h <= {model.height})"
            )
    goal = None
    if config.goal not in (GOAL_HERE, GOAL_SCENE) and not config.resume:
        goal = load_goal(config.goal, config.goal_box_px)
        if goal.kind != config.kind:
            raise CollectionInputError(f"--goal {config.goal}: a goal for a {goal.kind}, not a {config.kind}")
        if goal.image_size != (model.width, model.height):
            raise CollectionInputError(
                f"--goal {config.goal}: its image is {goal.image_size[0]}x{goal.image_size[1]} px, the "
                f"camera's {model.width}x{model.height}"
            )
    kinds = own_kinds_of([kind.name], {kind.name: kind_mapping(kind)})
    return CheckedInputs(model, goal, kinds)
