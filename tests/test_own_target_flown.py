"""A kind of one's own, flown: a small collection of a target no model has seen (a photograph), through
sim-mavlink (the real sim-vehicle process over MAVLink and MJPEG, MAVSDK), with the operator's box given in
a goal candidate; then the shipped detector and planner fine-tuned on it (the detector's head grows the
kind, the planner's tokenizer learns its words, both save them) and the fine-tuned planner evaluated.
CI-sized: a few captures per sector, one epoch each."""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import pytest
import yaml
from dronectl.cli import main as dronectl
from own_kinds import MUG, MUG_PHOTO

from controller.collection.config import FlownCollectConfig, SimOptions
from controller.collection.goal_flight import GoalError
from controller.collection.run import collect_flown
from controller.planning.latent.checkpoint import load_checkpoint
from drone_inspect_core.dataset import load_manifest
from perception.image_detector import SHIPPED_DIR, ImageDetector


def operator_box(candidate_png: Path) -> tuple[float, float, float, float]:
    """The mug's box (x, y, w, h) in the goal candidate, as an operator reads it off; here the photograph
    is found in the image by template matching over sizes."""
    photo = cv2.imread(str(MUG_PHOTO))
    image = cv2.imread(str(candidate_png))
    best = (-1.0, (0, 0), 0, 0)
    for width in range(20, 64):
        height = round(width * photo.shape[0] / photo.shape[1])
        template = cv2.resize(photo, (width, height), interpolation=cv2.INTER_AREA)
        _, score, _, corner = cv2.minMaxLoc(cv2.matchTemplate(image, template, cv2.TM_CCOEFF_NORMED))
        best = max(best, (score, corner, width, height))
    score, (x, y), width, height = best
    assert score > 0.6, score
    return float(x), float(y), float(width), float(height)


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    root = tmp_path_factory.mktemp("own")
    shutil.copy(MUG_PHOTO, root / "mug.png")
    scene = root / "mug.yaml"
    scene.write_text(
        yaml.safe_dump({"kinds": {"mug": {**MUG, "image": "mug.png"}}, "target": {"kinds": ["mug"]}})
    )
    first = FlownCollectConfig(
        out_dir=root / "first", vehicle="sim-mavlink", camera=None, kind="mug", goal="scene",
        progress=False, sim=SimOptions(scene_file=scene),
    )  # fmt: skip
    with pytest.raises(GoalError, match="goal candidate"):
        collect_flown(first)  # the shipped detector knows no mug: the goal is left as a candidate
    candidate = root / "first" / "goal_candidate.png"
    config = replace(
        first, out_dir=root / "data", goal=str(candidate.with_suffix(".json")),
        goal_box_px=operator_box(candidate), n_goal=3, n_per_sector=1, n_empty=1, block_size=3, test_every=2,
    )  # fmt: skip
    result = collect_flown(config)
    return {"root": root, "out": root / "data", "result": result}


def test_a_kind_of_ones_own_is_collected_from_the_operators_box(flown: dict[str, Any]) -> None:
    out = flown["out"]
    assert flown["result"].complete and flown["result"].flagged == 0
    rows, meta = load_manifest(out)
    assert meta["kinds"] == {"mug": {"noun": "mug", "train": ["mug", "coffee cup", "cup"]}}
    goal = json.loads((out / "goal.json").read_text())
    assert goal["box_source"] == "given" and goal["kind"] == "mug"
    for row in rows:
        if row["split"] != "empty":  # the operator's box in the goal image is what every label tracks
            assert math.dist(row["offset_px"], row["truth"]["offset_px"]) < 3.0, row["id"]


def test_the_shipped_models_learn_the_kind_from_the_flown_collection(
    flown: dict[str, Any], capsys: pytest.CaptureFixture[str]
) -> None:
    data, root = str(flown["out"]), flown["root"]
    detector = ["--epochs", "1", "--batch-size", "8", "--crop", "96", "--threads", "1"]
    assert (
        dronectl(
            [
                "train-detector",
                "--data",
                data,
                "--init",
                str(SHIPPED_DIR),
                "--out",
                str(root / "det"),
                *detector,
            ]
        )
        == 0
    )
    assert "added kinds: mug" in capsys.readouterr().out
    fine = ImageDetector.load(root / "det", backend="torch")
    assert fine.config.kinds == ("gauge", "valve", "switchbox", "mug")
    assert fine.own_kinds["mug"]["train"] == ["mug", "coffee cup", "cup"]
    planner = ["--preset", "own-target", "--epochs", "1", "--batch-size", "8", "--threads", "1", "--quiet"]
    assert dronectl(["train", "--data", data, "--out", str(root / "planner"), *planner]) == 0
    ckpt = load_checkpoint(root / "planner")
    assert ckpt.tokenizer.tokens("center the coffee cup")[3:5] == ["coffee", "cup"]  # whole words now
    assert ckpt.meta["kinds"]["mug"]["noun"] == "mug" and ckpt.meta["init"].endswith("latent_cpu")
    assert dronectl(["evaluate", "--model", str(root / "planner"), "--data", data]) == 0
    n_test = sum(1 for r in load_manifest(flown["out"])[0] if r["split"] == "test" and r["in_view"])
    assert f"images: {n_test} " in capsys.readouterr().out
