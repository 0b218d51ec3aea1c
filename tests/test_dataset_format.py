"""One dataset format for rendered and flown collections: what only a simulator knows is optional in a
flown dataset, flagged rows stay out of what the readers see, `dronectl dataset check` counts any dataset
and compares a flown-in-simulation dataset's labels with the truth's."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from dronectl.cli import main as dronectl

from drone_inspect_core.dataset import DatasetError, is_held_out, load_manifest
from drone_inspect_core.dataset_check import check_dataset

EPS = 10.0


def flown_row(index: int, split: str, offset: tuple[float, float], **extra: Any) -> dict[str, Any]:
    """A row as a flown collection writes it (no scene seed, no visible fraction, a label)."""
    du, dv = offset
    row = {
        "id": f"img_{index:06d}",
        "image": f"images/img_{index:06d}.png",
        "split": split,
        "sector": "centre" if split == "goal" else "E",
        "target_kind": "gauge",
        "centre_px": [112 + du, 112 + dv],
        "offset_px": [du, dv],
        "bbox_px": [100 + du, 100 + dv, 124 + du, 124 + dv],
        "in_view": True,
        "fully_in_view": True,
        "drone": {"position_ned_m": [0.0, 0.1 * index, -1.5], "yaw_deg": 0.0},
        "flight": 0,
        "block": index // 4,
        "time_s": 10.0 + index,
        "label": {"flagged": False, "pose_offset_px": [du + 1.0, dv]},
    }
    row.update(extra)
    return row


def write_flown(root: Path, rows: list[dict[str, Any]], meta: dict[str, Any] | None = None) -> Path:
    (root / "images").mkdir(parents=True)
    for row in rows:
        cv2.imwrite(str(root / row["image"]), np.zeros((224, 224, 3), np.uint8))
    base = {"source": "flown", "camera": {"width": 224, "height": 224}, "counts": {}, "epsilon_px": EPS}
    (root / "dataset.json").write_text(json.dumps({**base, **(meta or {})}))
    (root / "manifest.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return root


def test_a_flown_dataset_needs_no_simulator_fields_and_leaves_flagged_rows_out(tmp_path: Path) -> None:
    rows = [
        flown_row(0, "goal", (1.0, -2.0)),
        flown_row(1, "train", (40.0, 3.0)),
        flown_row(2, "train", (35.0, 0.0), label={"flagged": True, "reason": "disagree"}),
        flown_row(3, "test", (30.0, 2.0)),
    ]
    root = write_flown(tmp_path / "flown", rows)
    loaded, meta = load_manifest(root)
    assert [r["id"] for r in loaded] == ["img_000000", "img_000001", "img_000003"]
    assert len(load_manifest(root, include_flagged=True)[0]) == 4
    assert [is_held_out(r, meta) for r in loaded] == [False, False, True]


def test_a_flown_row_without_its_label_or_with_a_wrong_simulator_field_is_named(tmp_path: Path) -> None:
    no_label = flown_row(0, "train", (30.0, 0.0))
    del no_label["label"]
    with pytest.raises(DatasetError, match=r"manifest\.jsonl:1: missing field 'label'"):
        load_manifest(write_flown(tmp_path / "a", [no_label]))
    bad_depth = flown_row(0, "train", (30.0, 0.0), depth_m="far")
    with pytest.raises(DatasetError, match=r"manifest\.jsonl:1: field 'depth_m' has the wrong type"):
        load_manifest(write_flown(tmp_path / "b", [bad_depth]))
    with pytest.raises(DatasetError, match=r"dataset\.json: field 'source' is 'painted'"):
        load_manifest(write_flown(tmp_path / "c", [flown_row(0, "goal", (0, 0))], {"source": "painted"}))


def test_a_rendered_dataset_still_needs_its_simulator_fields(tmp_path: Path) -> None:
    row = flown_row(0, "train", (30.0, 0.0))
    root = write_flown(tmp_path / "r", [row], {"source": "rendered"})
    with pytest.raises(DatasetError, match=r"dataset\.json: missing field 'generator_version'"):
        load_manifest(root)


def test_dataset_check_counts_and_compares_labels_with_the_truth(tmp_path: Path) -> None:
    truth = {"offset_px": [40.0, 3.0], "in_view": True}
    rows = [
        flown_row(0, "goal", (1.0, -2.0), truth={"offset_px": [1.5, -2.0], "in_view": True}),
        flown_row(1, "train", (40.0, 3.0), truth=truth),
        # The image says E (du > ε), the truth says centre: a disagreement the check must count.
        flown_row(2, "train", (11.0, 0.0), truth={"offset_px": [9.0, 0.0], "in_view": True}),
        flown_row(3, "train", (35.0, 0.0), label={"flagged": True, "reason": "disagree"}, truth=truth),
    ]
    root = write_flown(tmp_path / "flown", rows)
    check = check_dataset(root)
    assert check.ok and check.rows == 4 and check.flagged == 1
    assert check.by_split == {"goal": 1, "train": 3}
    assert check.flagged_by_reason == {"disagree": 1}
    assert check.image_labels is not None and (check.image_labels.agree, check.image_labels.n) == (2, 3)
    assert check.image_labels.disagreeing == ["img_000002"]
    # Pose offsets are the label + 1 px: row 2's pose offset (12, 0) also disagrees with the truth.
    assert check.pose_labels is not None and (check.pose_labels.agree, check.pose_labels.n) == (2, 3)


def test_dataset_check_command_names_problems_and_writes_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = write_flown(tmp_path / "flown", [flown_row(0, "goal", (0, 0)), flown_row(1, "train", (30, 0))])
    (root / "images" / "img_000001.png").write_bytes(b"not a png")
    out = tmp_path / "check.json"
    assert dronectl(["dataset", "check", str(root), "--json", str(out)]) == 1
    text = capsys.readouterr().out
    assert "flown dataset, 2 images" in text and "img_000001.png: not a readable image" in text
    assert json.loads(out.read_text())["problems"]
    assert dronectl(["dataset", "check", str(tmp_path / "nowhere")]) == 2
    assert "no such dataset folder" in capsys.readouterr().err
