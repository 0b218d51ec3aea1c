"""`dronectl calibrate-presence`: the threshold chosen on validation scenes as the loop decides (the shipped
detector's match, then the presence head by kind), written to the checkpoint, read by the planner;
trained-on scenes refused; the checkpoint otherwise untouched. Validation scenes rendered afresh (a seed
no collection uses)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from dronectl.calibrate_presence_cmd import main

from controller.evaluation.presence import fewest_errors_threshold
from controller.evaluation.with_detector import evaluate_with_detector, loop_rates
from controller.planning.latent.checkpoint import CONFIG_FILE, load_checkpoint
from controller.planning.latent.planner import LatentPlanner
from controller.planning.planners import DEFAULT_CHECKPOINT
from perception.image_detector import ImageDetector
from sim_world.collection.collect import collect
from sim_world.collection.plan import CollectConfig
from sim_world.scene.config import DEFAULT_SCENE, with_targets

N = 24


@pytest.fixture
def checkpoint(tmp_path: Path) -> Path:
    """A copy of the shipped checkpoint without a calibrated threshold."""
    folder = tmp_path / "ckpt"
    shutil.copytree(DEFAULT_CHECKPOINT, folder)
    body = json.loads((folder / CONFIG_FILE).read_text())
    body["planner"] = {"mirror_tta": True}
    (folder / CONFIG_FILE).write_text(json.dumps(body, indent=2))
    return folder


@pytest.fixture(scope="module")
def validation(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("pval") / "data"
    scene = with_targets(DEFAULT_SCENE, count=(1, 3))  # each image lacks a kind or two to ask for
    cfg = CollectConfig(out_dir=out, seed=71_071, scene=scene, n_goal=1, n_per_sector=0, n_test=N, n_empty=0,
                        images_per_scene=3)  # fmt: skip
    collect(cfg, progress=False)
    return out


def _errors(present: tuple, absent: tuple, threshold: float) -> float:
    return sum(loop_rates(present, absent, threshold))


def test_the_threshold_makes_the_fewest_wrong_calls_as_the_loop_decides_and_is_written(
    checkpoint: Path, validation: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert LatentPlanner(checkpoint, backend="torch").presence_threshold is None  # uncalibrated: no verdict
    before = json.loads((checkpoint / CONFIG_FILE).read_text())
    assert main(["--model", str(checkpoint), "--data", str(validation)]) == 0
    out = capsys.readouterr().out
    assert "written to" in out and "as the loop decides" in out
    ckpt = load_checkpoint(checkpoint)
    threshold = ckpt.planner.presence_threshold
    assert threshold is not None and 0.0 < threshold < 1.0
    # The same reads the loop makes, with the checkpoint now calibrated: the pairs it was chosen on.
    reads = evaluate_with_detector(checkpoint, validation, ImageDetector.shipped())
    present, absent = reads.present_presence, reads.absent_presence
    assert len(present) == N and len(absent) > 0 and any(p is not None for p in present)
    assert threshold == pytest.approx(fewest_errors_threshold(present, absent))
    fewest = _errors(present, absent, threshold)
    assert all(fewest <= _errors(present, absent, t) + 1e-12 for t in np.linspace(0.001, 0.999, 999))
    assert reads.present_called_absent == pytest.approx(loop_rates(present, absent, threshold)[0])
    record = ckpt.planner.presence_calibration
    assert record["validation"] == [str(validation)] and record["detector"].startswith("shipped")
    assert record["validation_result"]["n_present"] == N and "fewest wrong calls" in record["rule"]
    after = json.loads((checkpoint / CONFIG_FILE).read_text())
    assert {k: v for k, v in after.items() if k != "planner"} == {
        k: v for k, v in before.items() if k != "planner"
    }
    assert LatentPlanner(checkpoint, backend="torch").presence_threshold == threshold  # what flies reads it


def test_the_rule_counts_unmatched_pairs_as_absent_and_takes_the_middle_of_the_widest_best_run() -> None:
    # Present p's 0.8, 0.9 and one the detector missed; absent p 0.2 and two unmatched. Any threshold in
    # (0.2, 0.8] is right on every matched pair: the middle, 0.5.
    assert fewest_errors_threshold([0.8, 0.9, None], [0.2, None, None]) == pytest.approx(0.5)
    # Nothing matched: no threshold changes anything, the middle of (0, 1).
    assert fewest_errors_threshold([None], [None]) == pytest.approx(0.5)
    # Overlap: present 0.3, 0.6, 0.7; absent 0.4, 0.5. Best is (0.5, 0.6] (one present missed, none
    # taken: 1/3) against (0, 0.3] (0 + 2/2) or (0.4, 0.5] (1/3 + 1/2).
    assert fewest_errors_threshold([0.3, 0.6, 0.7], [0.4, 0.5]) == pytest.approx(0.55)
    with pytest.raises(ValueError):
        fewest_errors_threshold([], [0.1])


def test_scenes_the_checkpoint_trained_on_are_refused_in_one_line_and_nothing_is_written(
    checkpoint: Path, validation: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    body = json.loads((checkpoint / CONFIG_FILE).read_text())
    seed = json.loads((validation / "manifest.jsonl").read_text().splitlines()[-1])["scene_seed"]
    body["dataset"]["meta"]["train_scene_seeds"].append(seed)  # a test scene of the validation folder
    (checkpoint / CONFIG_FILE).write_text(json.dumps(body, indent=2))
    assert main(["--model", str(checkpoint), "--data", str(validation), "--dry-run"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "of its test scenes trained the checkpoint" in err
    assert json.loads((checkpoint / CONFIG_FILE).read_text()) == body


def test_a_dry_run_writes_nothing_and_a_bad_detector_is_one_line(
    checkpoint: Path, validation: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    before = (checkpoint / CONFIG_FILE).read_bytes()
    assert main(["--model", str(checkpoint), "--data", str(validation), "--dry-run"]) == 0
    assert "not written" in capsys.readouterr().out
    assert (checkpoint / CONFIG_FILE).read_bytes() == before
    (tmp_path / "nodet").mkdir()
    assert (
        main(["--model", str(checkpoint), "--data", str(validation), "--detector", str(tmp_path / "nodet")])
        == 1
    )
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert (checkpoint / CONFIG_FILE).read_bytes() == before
