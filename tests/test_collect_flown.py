"""The collection protocol flown through the Vehicle interface, end to end through sim-mavlink (the real
sim-vehicle process over MAVLink and MJPEG, MAVSDK, the .tlog relay), at the simulator's full speed.

One small collection is flown twice: the first flight loses its uplink after a few captures (the relay
stops forwarding the controller's messages), so the vehicle fails safe into a hold while the captures so
far stay on disk and the dataset says it is incomplete; `--resume` then flies the rest. The finished
dataset holds every planned capture exactly once, its labels agree with the simulator's truth, and the
planner and the detector train on it and are evaluated on it. Bad input is refused in one line before
anything is launched.
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from dronectl.cli import main as dronectl

from controller.collection.config import FlownCollectConfig
from controller.collection.run import collect_flown
from drone_inspect_core.dataset import load_manifest
from drone_inspect_core.dataset_check import check_dataset
from flight.errors import FlightError

CUT_AFTER = 5


class UplinkCut:
    """After `CUT_AFTER` captures: cut the uplink, then watch the simulator's truth until it is gone."""

    def __init__(self) -> None:
        self.truth: list[dict[str, Any]] = []
        self.cut_at_row: str | None = None
        self._thread: threading.Thread | None = None

    def __call__(self, row: dict[str, Any], opened: Any, sim: Any) -> None:
        if self.cut_at_row is not None or int(row["id"].split("_")[1]) + 1 < CUT_AFTER:
            return
        self.cut_at_row = row["id"]
        opened.tlog.drop_uplink = True
        self._thread = threading.Thread(target=self._watch, args=(sim,), daemon=True)
        self._thread.start()

    def _watch(self, sim: Any) -> None:
        for _ in range(600):
            frame = sim.truth.frame()
            if frame is None:
                return
            self.truth.append(frame["drone"])
            time.sleep(0.05)


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("flown") / "data"
    config = FlownCollectConfig(
        out_dir=out, vehicle="sim-mavlink", camera=None, kind="gauge", goal="scene",
        n_goal=3, n_per_sector=2, n_empty=2, block_size=3, test_every=2, progress=False,
    )  # fmt: skip
    cut = UplinkCut()
    with pytest.raises(FlightError):
        collect_flown(config, on_capture=cut)
    first_rows, first_meta = load_manifest(out, include_flagged=True)
    resumed = collect_flown(replace(config, resume=True))
    return {"out": out, "cut": cut, "first_rows": first_rows, "first_meta": first_meta, "resumed": resumed}


def test_a_lost_uplink_holds_and_keeps_the_captures(flown: dict[str, Any]) -> None:
    cut, rows, meta = flown["cut"], flown["first_rows"], flown["first_meta"]
    assert cut.cut_at_row is not None and len(rows) >= CUT_AFTER
    assert meta["complete"] is False and "Offboard" in meta["flights"][0]["ended_by"]
    assert all((flown["out"] / row["image"]).is_file() for row in rows)
    # The vehicle's own failsafe holds it: after the cut it never flies off (the sim lands it later).
    assert len(cut.truth) >= 5
    speeds = [math.hypot(*d["velocity_ned_m_s"][:2]) for d in cut.truth[len(cut.truth) // 3 :]]
    assert max(speeds) < 0.3, speeds


def test_resume_takes_every_planned_capture_exactly_once(flown: dict[str, Any]) -> None:
    out, resumed = flown["out"], flown["resumed"]
    assert resumed.complete
    plan = [c["id"] for c in json.loads((out / "plan.json").read_text())["captures"]]
    rows, meta = load_manifest(out, include_flagged=True)
    assert sorted(row["id"] for row in rows) == sorted(plan)  # each once, none lost, none twice
    assert len({row["image"] for row in rows}) == len(rows)
    assert {row["flight"] for row in rows} == {0, 1} and len(meta["flights"]) == 2
    assert meta["complete"] is True and (out / "contact_sheet.png").is_file()
    assert (out / "flights" / "0" / "flight.tlog").is_file() and (
        out / "flights" / "1" / "flight.tlog"
    ).is_file()


def test_the_flown_labels_agree_with_the_simulators_truth(flown: dict[str, Any]) -> None:
    check = check_dataset(flown["out"])
    assert check.ok and check.source == "flown" and check.flagged <= 1
    assert {"goal", "train", "test", "empty"} <= set(check.by_split)
    assert check.image_labels is not None and check.image_labels.agree == check.image_labels.n > 10
    rows, _ = load_manifest(flown["out"])
    for row in rows:
        if row["split"] != "empty":
            assert math.dist(row["offset_px"], row["truth"]["offset_px"]) < 3.0, row["id"]
            assert row["label"]["distance_source"] == "rangefinder"


def test_the_planner_and_the_detector_train_on_a_flown_dataset_and_are_evaluated(
    flown: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = str(flown["out"])
    train = ["--epochs", "1", "--image-size", "64", "--width", "8", "--threads", "1", "--batch-size", "8"]
    assert dronectl(["train", "--data", data, "--out", str(tmp_path / "planner"), *train]) == 0
    assert (tmp_path / "planner" / "model.safetensors").is_file()
    assert dronectl(["evaluate", "--model", str(tmp_path / "planner"), "--data", data]) == 0
    n_test = sum(1 for r in load_manifest(flown["out"])[0] if r["split"] == "test" and r["in_view"])
    assert f"images: {n_test} " in capsys.readouterr().out
    detector = ["--epochs", "1", "--batch-size", "8", "--crop", "64"]
    assert dronectl(["train-detector", "--data", data, "--out", str(tmp_path / "det"), *detector]) == 0
    assert (tmp_path / "det" / "model.safetensors").is_file()


BAD = [
    (["--kind", "gauge", "--out", "{out}"], "--goal: say where the goal is"),
    (["--kind", "gauge", "--goal", "scene", "--out", "{out}", "--box-m", "2"], "does not fit the geofence"),
    (["--kind", "gauge", "--goal", "scene", "--out", "{out}", "--distance-m", "0"], "--distance-m must be"),
    (["--kind", "flange", "--goal", "scene", "--out", "{out}"], "--kind: unknown target kind 'flange'"),
    (
        ["--kind", "gauge", "--goal", "{tmp}/nowhere.json", "--out", "{out}"],
        "nowhere.json: no such goal file",
    ),
    (["--kind", "gauge", "--goal", "{tmp}/garbage.json", "--out", "{out}"], "garbage.json: unreadable"),
    (
        ["--kind", "gauge", "--goal", "scene", "--goal-box", "200,100,40,30", "--out", "{out}"],
        "--goal-box 200,100,40,30 does not lie inside the camera's 224x224 image",
    ),
    (
        ["--kind", "gauge", "--kinds", "{tmp}/kinds.yaml", "--goal", "scene", "--out", "{out}"],
        "the kind 'gauge' is given twice (also in the shipped vocabulary)",
    ),
    (["--kind", "mug", "--goal", "scene", "--out", "{out}"], "--kind: unknown target kind 'mug'"),
]


@pytest.mark.parametrize(("args", "message"), BAD)
def test_bad_input_is_one_named_line_before_anything_flies(
    args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "garbage.json").write_text("{not json")
    (tmp_path / "kinds.yaml").write_text("kinds: {gauge: {words: [gauge, dial]}}\n")
    argv = [
        "collect",
        "--vehicle",
        "sim-mavlink",
        *(a.format(out=tmp_path / "out", tmp=tmp_path) for a in args),
    ]
    assert dronectl(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "out").exists()  # nothing claimed, nothing launched


def test_a_real_vehicle_needs_a_camera_file_with_intrinsics(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bare = tmp_path / "camera.yaml"
    bare.write_text("width: 640\nheight: 480\n")
    real = ["collect", "--vehicle", "udpin://127.0.0.1:14997", "--camera", "http://127.0.0.1:9/x.mjpg"]
    common = ["--kind", "gauge", "--goal", "here", "--out", str(tmp_path / "out")]
    assert dronectl([*real, *common]) == 2
    assert "--camera-file: a real vehicle's camera needs its intrinsics" in capsys.readouterr().err
    assert dronectl([*real, *common, "--camera-file", str(bare)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "camera.yaml: intrinsics: none given" in err[0]
    assert dronectl([*real, *common, "--camera-file", str(tmp_path / "none.yaml")]) == 2
    assert "none.yaml: no such file" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
