"""The detector learns a kind of one's own from a few images: `train-detector --init` grows the shipped
detector's head by the kind, saves the kind's words with the checkpoint, and afterwards finds the new face
on renders it never trained on, which the shipped detector cannot. Bad input to the new options is one
named line before anything trains."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest
import torch
import yaml
from dronectl.cli import main as dronectl
from own_kinds import MUG, MUG_PHOTO

from controller.planning.planners import DEFAULT_CHECKPOINT
from drone_inspect_core.centring import default_epsilon_px
from drone_inspect_core.dataset import load_manifest, read_image_rgb
from perception.detector_model import CentreNet, DetectorConfig, grow_kinds
from perception.image_detector import SHIPPED_DIR, ImageDetector, load_model
from perception.training.train import TrainDetectorConfig, train_detector
from sim_world.collection.collect import CollectConfig, collect
from sim_world.scene.config import load_scene_config


@pytest.fixture(scope="module")
def renders(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny rendered collection of the mug (its training scenes) and held-out renders (other scenes)."""
    root = tmp_path_factory.mktemp("mug")
    shutil.copy(MUG_PHOTO, root / "mug.png")
    scene = root / "mug.yaml"
    scene.write_text(
        yaml.safe_dump({"kinds": {"mug": {**MUG, "image": "mug.png"}}, "target": {"kinds": ["mug"]}})
    )
    config = CollectConfig(
        out_dir=root / "data", seed=5, scene=load_scene_config(scene), scene_file=str(scene),
        n_goal=8, n_per_sector=4, n_test=16, n_empty=0, images_per_scene=4, distance_m=(1.5, 2.5),
    )  # fmt: skip
    collect(config, progress=False)
    return root / "data"


def mug_hits(detector: ImageDetector, data: Path) -> tuple[int, int]:
    """(test renders where a detection of kind mug lies within ε of the truth's centre, test renders)."""
    rows, _ = load_manifest(data)
    test = [r for r in rows if r["split"] == "test" and r["fully_in_view"]]
    hits = 0
    for row in test:
        found = detector.detect_all(read_image_rgb(data / row["image"]))
        hits += any(d.kind == "mug" and math.dist(d.centre_px, row["centre_px"]) <= default_epsilon_px(224)
                    for d in found)  # fmt: skip
    return hits, len(test)


def test_the_head_grows_a_kind_and_keeps_what_it_knew() -> None:
    model = CentreNet(DetectorConfig(input_size=64, widths=(8, 8, 8, 8, 8), neck_width=8)).eval()
    grown = grow_kinds(model, ("gauge", "mug")).eval()
    assert grown.config.kinds == ("gauge", "valve", "switchbox", "mug")
    x = torch.randn(2, 3, 64, 64, generator=torch.Generator().manual_seed(0))
    before, after = model(x), grown(x)
    assert torch.equal(after[:, :3], before[:, :3]) and torch.equal(after[:, 4:], before[:, 3:])
    assert grow_kinds(grown, ("mug",)) is grown  # nothing to add: the same network


@pytest.mark.slow
def test_the_detector_learns_a_new_kind_from_a_few_images(renders: Path, tmp_path: Path) -> None:
    torch.set_num_threads(2)
    before, n = mug_hits(ImageDetector.shipped(backend="torch"), renders)
    assert n >= 10 and before == 0  # the shipped detector has no mug
    config = TrainDetectorConfig(
        data_dir=renders, out_dir=tmp_path / "det", init_dir=SHIPPED_DIR, epochs=6, batch_size=8,
        crop_px=96, lr=1e-3, val_fraction=0.0, seed=1,
    )  # fmt: skip
    result = train_detector(config)
    assert result.added == ("mug",) and result.kinds == ("gauge", "valve", "switchbox", "mug")
    saved = json.loads((tmp_path / "det" / "config.json").read_text())
    assert saved["kinds"]["mug"]["train"] == ["mug", "coffee cup", "cup"]
    after, _ = mug_hits(ImageDetector.load(tmp_path / "det", backend="torch"), renders)
    assert after >= 0.4 * n, (after, n)  # 11 of 16 here (2026-11-26); none without the added kind


def test_bad_input_to_the_new_options_is_one_named_line(
    renders: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    def one_line(argv: list[str], message: str) -> None:
        assert dronectl(argv) != 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
        assert not (tmp_path / "out").exists()  # nothing trained, no run folder

    data = str(renders)
    one_line(
        ["train-detector", "--data", data, "--init", str(DEFAULT_CHECKPOINT), "--out", str(tmp_path / "out")],
        "config.json: field 'format' must be 'drone-inspect/detector/1'",
    )
    one_line(
        ["train", "--data", data, "--init", str(SHIPPED_DIR), "--out", str(tmp_path / "out")],
        "checkpoint file missing",
    )
    other = tmp_path / "other"  # the same kind given other words in another dataset
    shutil.copytree(renders, other)
    meta = json.loads((other / "dataset.json").read_text())
    meta["scene_config"]["kinds"]["mug"]["train"] = ["mug", "beaker"]
    (other / "dataset.json").write_text(json.dumps(meta))
    one_line(
        [
            "train-detector",
            "--data",
            data,
            "--extra",
            str(other),
            "--init",
            str(SHIPPED_DIR),
            "--out",
            str(tmp_path / "out"),
        ],
        "the kind 'mug' is given twice, differently",
    )
    one_line(
        ["train", "--data", data, str(other), "--preset", "own-target", "--out", str(tmp_path / "out")],
        "the kind 'mug' is given twice, differently",
    )
    assert load_model(SHIPPED_DIR).config.kinds == ("gauge", "valve", "switchbox")
