"""Collection in scenes of several targets: `dronectl collect --targets 3` writes every target's
truth per row (the named one's equal to the row's own fields), empty images with no target in
view, and datasets written before these fields still load."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from drone_inspect_core.dataset import DatasetError, load_manifest, row_targets
from dronectl.collect_cmd import main as collect_main
from dronectl.collect_cmd import target_count

TRUTH = ("centre_px", "offset_px", "bbox_px", "in_view", "fully_in_view", "visible_fraction", "depth_m")
SMALL = ["--n-goal", "2", "--n-per-sector", "1", "--n-test", "3", "--n-empty", "4", "--size", "80"]
SMALL += ["--images-per-scene", "8", "--workers", "1", "--no-progress"]


@pytest.fixture(scope="module")
def three_target_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("collect_multi") / "three"
    assert collect_main(["--out", str(out), "--seed", "3", "--targets", "3", *SMALL]) == 0
    return out


def test_rows_list_every_target_with_the_named_one_first(three_target_dataset: Path) -> None:
    rows, meta = load_manifest(three_target_dataset)
    assert meta["protocol"]["targets"] == [3, 3] and meta["protocol"]["twins"] is False
    assert meta["scene_config"]["target"]["count"] == [3, 3]
    assert meta["counts"] == {"goal": 2, "train": 8, "test": 3, "empty": 4}
    for row in rows:
        targets = row["targets"]
        assert row["named"] == 0 and len(targets) == 3
        named = targets[row["named"]]
        assert named["kind"] == row["target_kind"] and named["attribute"] == row["target_attribute"]
        assert {k: named[k] for k in TRUTH} == {k: row[k] for k in TRUTH}, row["id"]
        assert len({t["kind"] for t in targets}) == 3
        assert row_targets(row) == targets
        if row["split"] == "empty":
            assert not any(t["in_view"] or t["bbox_px"] is not None for t in targets), row["id"]
            assert all(t["visible_fraction"] == 0.0 for t in targets), row["id"]
        else:
            assert named["in_view"], row["id"]


def test_single_target_rows_carry_a_one_element_list(tmp_path: Path) -> None:
    out = tmp_path / "one"
    argv = ["--out", str(out), "--seed", "3", "--n-goal", "1", "--n-per-sector", "1", "--n-test", "0"]
    argv += ["--n-empty", "0", "--size", "64", "--images-per-scene", "9", "--workers", "1", "--no-progress"]
    assert collect_main(argv) == 0
    rows, meta = load_manifest(out)
    assert meta["protocol"]["targets"] == [1, 1]
    for row in rows:
        assert row["named"] == 0 and len(row["targets"]) == 1
        assert {k: row["targets"][0][k] for k in TRUTH} == {k: row[k] for k in TRUTH}


def test_targets_option_takes_a_number_or_a_range(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert target_count("3") == (3, 3) and target_count("2-4") == (2, 4)
    with pytest.raises(argparse.ArgumentTypeError):
        target_count("two")
    assert collect_main(["--out", str(tmp_path / "a"), "--seed", "0", "--targets", "5", *SMALL]) == 2
    assert "target.count" in capsys.readouterr().err
    assert collect_main(["--out", str(tmp_path / "b"), "--seed", "0", "--twins", *SMALL]) == 2
    assert "--twins" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_old_rows_without_the_target_list_still_load(three_target_dataset: Path, tmp_path: Path) -> None:
    rows, _ = load_manifest(three_target_dataset)
    old = {k: v for k, v in rows[0].items() if k not in ("target_attribute", "named", "targets")}
    meta = {
        "generator_version": "sim_world.collect/2",
        "seed": 0,
        "camera": {},
        "scene_config": {},
        "counts": {},
    }
    folder = tmp_path / "old"
    (folder / "images").mkdir(parents=True)
    (folder / "dataset.json").write_text(json.dumps(meta))
    (folder / "manifest.jsonl").write_text(json.dumps(old) + "\n")
    loaded, _ = load_manifest(folder, check_images=False)
    assert row_targets(loaded[0]) == [rows[0]["targets"][0]]  # rebuilt from the row's own fields

    bad = dict(rows[0], named=3)
    (folder / "manifest.jsonl").write_text(json.dumps(bad) + "\n")
    with pytest.raises(DatasetError, match=r"manifest\.jsonl:1: field 'named' must index 'targets'"):
        load_manifest(folder, check_images=False)
    bad = dict(rows[0], targets=[{k: v for k, v in rows[0]["targets"][0].items() if k != "depth_m"}])
    (folder / "manifest.jsonl").write_text(json.dumps(bad) + "\n")
    with pytest.raises(DatasetError, match=r"missing field 'targets\[0\]\.depth_m'"):
        load_manifest(folder, check_images=False)
