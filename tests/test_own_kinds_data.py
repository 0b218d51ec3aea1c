"""A kind of one's own travels with the data made from it: a kinds file names it for a real vehicle's
collection, the dataset records its words, a goal candidate waits for the operator's box, checkpoints
carry the words on to missions; a kind given twice with other words is refused, naming both places."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from controller.collection.config import FlownCollectConfig
from controller.collection.goal import CANDIDATE, GoalFileError, GoalRecord, load_goal, save_goal
from controller.collection.inputs import CollectionInputError, check_inputs
from controller.missions.schema import MissionFileError, parse_mission
from drone_inspect_core.own_kinds import KindConflictError, checkpoint_kinds, dataset_kinds, merge_kinds
from perception.camera_model import CameraModel, PoseNed

FLANGE = {"flange": {"words": ["flange", "pipe flange"]}}


def real_config(tmp_path: Path, **changes: object) -> FlownCollectConfig:
    camera = tmp_path / "camera.yaml"
    camera.write_text("width: 320\nheight: 240\nhfov_deg: 70\n")
    kinds = tmp_path / "kinds.yaml"
    kinds.write_text(json.dumps({"kinds": FLANGE}))
    fields: dict[str, object] = {
        "out_dir": tmp_path / "out", "vehicle": "udpin://127.0.0.1:14997", "camera": "http://127.0.0.1:9/x",
        "camera_file": camera, "kinds_file": kinds, "kind": "flange", "goal": "here",
    }  # fmt: skip
    return FlownCollectConfig(**{**fields, **changes})  # type: ignore[arg-type]


def test_a_kinds_file_names_a_real_vehicles_target_and_the_dataset_records_its_words(tmp_path: Path) -> None:
    checked = check_inputs(real_config(tmp_path))
    assert checked.kinds == {"flange": {"noun": "flange", "train": ["flange", "pipe flange"]}}
    assert check_inputs(real_config(tmp_path, kind="gauge")).kinds == {}  # a shipped kind needs no record
    with pytest.raises(CollectionInputError, match="--kind: unknown target kind 'flange'"):
        check_inputs(real_config(tmp_path, kinds_file=None))
    with pytest.raises(CollectionInputError, match=r"--goal-box 300,10,40,30 does not lie inside .* 320x240"):
        check_inputs(real_config(tmp_path, goal_box_px=(300.0, 10.0, 40.0, 30.0)))
    (tmp_path / "bad.yaml").write_text("kinds: {flange: {words: [flange], colour: red}}\n")
    with pytest.raises(CollectionInputError, match="unknown field 'colour'"):
        check_inputs(real_config(tmp_path, kinds_file=tmp_path / "bad.yaml"))
    assert dataset_kinds({"kinds": checked.kinds}) == checked.kinds
    assert dataset_kinds({"scene_config": {"kinds": FLANGE}}) == FLANGE and dataset_kinds({}) == {}


def test_a_goal_candidate_waits_for_the_operators_box(tmp_path: Path) -> None:
    camera = CameraModel.from_fov(224, 224, 60.0)
    image = np.zeros((224, 224, 3), np.uint8)
    goal = GoalRecord(PoseNed(0.0, 0.0, -1.5, 0.0), None, 2.0, "given", "none", "flange", (224, 224), image)
    path = save_goal(goal, camera, tmp_path, CANDIDATE)
    assert path.name == "goal_candidate.json" and (tmp_path / "goal_candidate.png").is_file()
    with pytest.raises(GoalFileError, match=r"a goal candidate without the target's box: .*--goal-box"):
        load_goal(path)
    given = load_goal(path, (100.0, 90.0, 20.0, 30.0))
    assert given.box_px == (100.0, 90.0, 120.0, 120.0) and given.box_source == "given"
    assert given.offset_px == (-2.0, -7.0)


def test_a_kind_given_twice_with_other_words_names_both_places() -> None:
    same = merge_kinds([("a", FLANGE), ("b", FLANGE), ("c", {"gauge": {"words": ["gauge"]}})])
    assert list(same) == ["flange"]  # shipped kinds are everyone's: not carried
    other = {"flange": {"words": ["flange", "collar"]}}
    with pytest.raises(KindConflictError, match=r"'flange' is given twice, differently: a says .* b says"):
        merge_kinds([("a", FLANGE), ("b", other)])


def test_a_mission_may_name_a_kind_its_checkpoints_know(tmp_path: Path) -> None:
    detector = tmp_path / "det"
    detector.mkdir()
    (detector / "config.json").write_text(json.dumps({"format": "x", "kinds": FLANGE}))
    assert checkpoint_kinds(detector)["flange"]["train"] == ["flange", "pipe flange"]
    mission = parse_mission({"name": "m", "target_kind": "flange", "detector_checkpoint": str(detector)})
    assert mission.vocabulary.kind("flange").noun == "flange"
    with pytest.raises(MissionFileError, match="target_kind: unknown target kind 'flange'"):
        parse_mission({"name": "m", "target_kind": "flange"})
