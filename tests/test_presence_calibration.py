"""`dronectl calibrate-presence`: the threshold chosen on validation folders, written to the checkpoint,
read by the planner; trained-on scenes refused; the checkpoint otherwise untouched."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from dronectl.calibrate_presence_cmd import main
from latent_synthetic import write_synthetic_dataset

from controller.evaluation.presence import choose_threshold, kind_presence_pairs
from controller.planning.latent.checkpoint import CONFIG_FILE, load_checkpoint
from controller.planning.latent.planner import LatentPlanner
from controller.planning.planners import DEFAULT_CHECKPOINT
from controller.training.data import load_images, load_index


@pytest.fixture
def checkpoint(tmp_path: Path) -> Path:
    """A copy of the shipped checkpoint without a calibrated threshold."""
    folder = tmp_path / "ckpt"
    shutil.copytree(DEFAULT_CHECKPOINT, folder)
    body = json.loads((folder / CONFIG_FILE).read_text())
    body["planner"] = {"mirror_tta": True}
    (folder / CONFIG_FILE).write_text(json.dumps(body, indent=2))
    return folder


@pytest.fixture
def validation(tmp_path: Path) -> Path:
    # Two targets of three kinds per image: each image has one kind to ask for that it lacks.
    return write_synthetic_dataset(
        tmp_path / "val", n_goal=1, n_train=1, n_test=40, size=64, seed=3, targets=2
    )


def test_the_chosen_threshold_is_written_and_meets_its_budget_on_the_validation_pairs(
    checkpoint: Path, validation: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert LatentPlanner(checkpoint, backend="torch").presence_threshold is None  # uncalibrated: no verdict
    before = json.loads((checkpoint / CONFIG_FILE).read_text())
    assert main(["--model", str(checkpoint), "--data", str(validation), "--max-false-absent", "0.05"]) == 0
    assert "written to" in capsys.readouterr().out
    ckpt = load_checkpoint(checkpoint)
    threshold = ckpt.planner.presence_threshold
    index = load_index(validation)
    data = load_images(index.split("test"), ckpt.config.image_size, index.default_epsilon_px())
    present, absent = kind_presence_pairs(ckpt, data, None, mirror=True)  # as the loop asks, mirrored
    assert len(present) == 40 and len(absent) == 40
    assert threshold == pytest.approx(choose_threshold(present, absent, 0.05))
    assert np.mean(present < threshold) <= 0.05
    record = ckpt.planner.presence_calibration
    assert record["validation"] == [str(validation)] and record["max_false_absent"] == 0.05
    after = json.loads((checkpoint / CONFIG_FILE).read_text())
    assert {k: v for k, v in after.items() if k != "planner"} == {
        k: v for k, v in before.items() if k != "planner"
    }
    assert LatentPlanner(checkpoint, backend="torch").presence_threshold == threshold  # what flies reads it


def test_scenes_the_checkpoint_trained_on_are_refused_in_one_line_and_nothing_is_written(
    checkpoint: Path, validation: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    body = json.loads((checkpoint / CONFIG_FILE).read_text())
    body["dataset"]["meta"]["train_scene_seeds"].append(3500)  # a test scene of the validation folder
    (checkpoint / CONFIG_FILE).write_text(json.dumps(body, indent=2))
    assert main(["--model", str(checkpoint), "--data", str(validation), "--dry-run"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "1 of its test scenes trained the checkpoint" in err
    assert json.loads((checkpoint / CONFIG_FILE).read_text()) == body


def test_a_dry_run_writes_nothing(
    checkpoint: Path, validation: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = (checkpoint / CONFIG_FILE).read_bytes()
    assert main(["--model", str(checkpoint), "--data", str(validation), "--dry-run"]) == 0
    assert "not written" in capsys.readouterr().out
    assert (checkpoint / CONFIG_FILE).read_bytes() == before
