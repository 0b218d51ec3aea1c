"""`dronectl reproduce --experiments grounded`: seeds, the held-out look's matched gap, resuming."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from latent_synthetic import write_synthetic_dataset

from controller.evaluation.reproduce_grounded import (
    LOOK,
    look_gap,
    named_test_sets,
    reproduce_grounded,
    summarise,
)


def _cell(n: int, rank1: float) -> dict[str, float]:
    return {"n": n, "rank1": rank1}


def test_look_gap_compares_like_with_like_and_leaves_twins_out() -> None:
    summary = {
        "tests": {
            "paper": {"by_targets_in_view": {"1": _cell(20, 1.0)}, "twins": False},
            "multi": {"by_targets_in_view": {"1": _cell(20, 0.95), "2": _cell(10, 0.9)}, "twins": False},
            "twins": {"by_targets_in_view": {"2": _cell(50, 0.5)}, "twins": True},  # harder: not a reference
            LOOK: {"by_targets_in_view": {"1": _cell(10, 0.9), "2": _cell(30, 0.8), "4": _cell(5, 0.0)}},
        }
    }
    gap = look_gap(summary)
    assert gap is not None
    # Weighted by the look set's own mix (10 one-target, 30 two-target images); its 4-target images
    # have no in-distribution counterpart and are left out of both sides.
    assert gap["in_distribution"] == pytest.approx((10 * (20 * 1.0 + 20 * 0.95) / 40 + 30 * 0.9) / 40)
    assert gap["heldout"] == pytest.approx((10 * 0.9 + 30 * 0.8) / 40)
    assert look_gap({"tests": {"paper": summary["tests"]["paper"]}}) is None


def test_kind_matched_gap_takes_the_draw_of_kinds_out() -> None:
    """A held-out set that drew more of the hardest kind looks worse matched on targets alone; matched on
    the named kind as well, the same per-kind accuracy is no gap."""
    by_kind = {"gauge/1": _cell(20, 1.0), "switchbox/1": _cell(20, 0.8)}
    look_kinds = {"gauge/1": _cell(10, 1.0), "switchbox/1": _cell(30, 0.8)}
    summary = {
        "tests": {
            "paper": {
                "by_targets_in_view": {"1": _cell(40, 0.9)},
                "by_kind_and_targets": by_kind,
                "twins": False,
            },
            LOOK: {"by_targets_in_view": {"1": _cell(40, 0.85)}, "by_kind_and_targets": look_kinds},
        }
    }
    plain = look_gap(summary)
    kind = look_gap(summary, by="by_kind_and_targets")
    assert plain is not None and kind is not None
    assert plain["in_distribution"] - plain["heldout"] == pytest.approx(0.05)
    assert kind["heldout"] == pytest.approx(0.85)
    assert kind["in_distribution"] == pytest.approx(0.85)  # (10 · 1.0 + 30 · 0.8) / 40
    del summary["tests"][LOOK]["by_kind_and_targets"]  # an eval.json from before the grouping
    assert look_gap(summary, by="by_kind_and_targets") is None


def test_summary_spreads_over_seeds() -> None:
    def seed(s: int, r: float) -> dict:
        return {
            "seed": s,
            "train_seconds": 100.0 + s,
            "tests": {"multi": {"rank1": r, "n": 4, "auroc": 0.9, "by_targets_in_view": {}, "twins": False}},
        }

    table = summarise([seed(0, 0.9), seed(1, 0.8), seed(2, 1.0)])
    cell = table["tests"]["multi"]["rank1"]
    assert cell["mean"] == pytest.approx(0.9) and cell["sd"] == pytest.approx(0.1)
    assert (cell["min"], cell["max"]) == (0.8, 1.0)
    assert "look_gap" not in table  # no held-out look given


def test_test_sets_need_distinct_names(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="distinct"):
        named_test_sets([tmp_path / "a" / "multi", tmp_path / "b" / "multi"], None)
    with pytest.raises(ValueError, match="no test folder"):
        named_test_sets([], None)


TINY = {"image_size": 32, "base_width": 4}  # the grounded preset's model, shrunk: minutes to seconds


@pytest.mark.timeout(600)
def test_grounded_reproduction_trains_each_seed_once_and_reports(tmp_path: Path) -> None:
    one = write_synthetic_dataset(tmp_path / "one", n_goal=16, n_train=64, n_test=16, seed=1)
    two = write_synthetic_dataset(tmp_path / "two", n_goal=16, n_train=64, n_test=24, seed=2, targets=2)
    look = write_synthetic_dataset(tmp_path / "look", n_goal=4, n_train=8, n_test=16, seed=3, targets=2)
    out = tmp_path / "report"
    report = reproduce_grounded(
        [one, two], [one, two], look, out, seeds=2, epochs=1, model_overrides=TINY,
        train_overrides={"shift_init_std": 0.25},
    )  # fmt: skip
    text = report.read_text()
    # the recipe under test named, the model's changes too
    assert "with `--preset grounded` (base_width = 4, image_size = 32, shift_init_std = 0.25);" in text
    assert "| one (" in text and "| two (" in text and f"| {LOOK} (" in text and text.count("gap:") == 4
    assert "## With its mirror image" in text  # every test set also scored as the planner can run
    data = json.loads((out / "grounded.json").read_text())
    assert [s["seed"] for s in data["seeds"]] == [0, 1]
    assert set(data["seeds"][0]["tests"]) == set(data["seeds"][0]["tests_mirror"]) == {"one", "two", LOOK}
    assert {"look_gap", "look_gap_kind", "look_gap_mirror", "look_gap_mirror_kind"} <= set(data["summary"])
    assert data["seeds"][0]["epochs"] == 1
    assert data["seeds"][1]["train_overrides"] == {"shift_init_std": 0.25}  # the recipe under test, trained
    run_config = json.loads((out / "runs" / "grounded_s1" / "config.json").read_text())
    assert run_config["train"]["shift_init_std"] == 0.25
    # A second call reuses both seeds: it needs no training data, and changes nothing recorded.
    before = (out / "runs" / "grounded_s0" / "eval.json").read_text()
    (out / "runs" / "grounded_s1" / "eval.json").unlink()  # seed 1: trained, not yet evaluated
    again = reproduce_grounded(
        [tmp_path / "gone"], [one, two], look, out, seeds=2, epochs=1, model_overrides=TINY
    )
    assert again == report
    assert (out / "runs" / "grounded_s0" / "eval.json").read_text() == before
    assert json.loads((out / "grounded.json").read_text())["seeds"][1]["tests"]["two"]["n"] == 24
    # A finished run is not reported as another recipe's: not at another width, not as another seed.
    (out / "runs" / "grounded_s1" / "eval.json").unlink()
    with pytest.raises(
        ValueError, match=r"grounded_s0: a finished run with model base_width = 4, .* asks for 5"
    ):
        reproduce_grounded(
            [one], [one], None, out, seeds=2, epochs=1, model_overrides={**TINY, "base_width": 5}
        )
    (out / "runs" / "grounded_s0").rename(tmp_path / "seed0")
    (out / "runs" / "grounded_s1").rename(out / "runs" / "grounded_s0")
    with pytest.raises(ValueError, match=r"grounded_s0: a finished run with train seed = 1, .* asks for 0"):
        reproduce_grounded([one], [one], None, out, seeds=1, epochs=1, model_overrides=TINY)
    (out / "runs" / "grounded_s0").rename(out / "runs" / "grounded_s1")
    (tmp_path / "seed0").rename(out / "runs" / "grounded_s0")  # evaluated: checked all the same
    with pytest.raises(ValueError, match=r"grounded_s0: .* train shift_init_std = 0.25, .* asks for 0.5"):
        reproduce_grounded(
            [one], [one], None, out, seeds=1, model_overrides=TINY, train_overrides={"shift_init_std": 0.5}
        )


@pytest.mark.parametrize(
    "option",
    [
        ["--shift-init-std", "0.5"],
        ["--distill-from", "teacher"],
        ["--distill-weight", "2"],
        ["--width", "24"],
    ],
)
def test_a_recipe_override_is_refused_outside_the_grounded_experiment(
    tmp_path: Path, option: list[str]
) -> None:
    from dronectl.reproduce_cmd import main

    with pytest.raises(SystemExit, match=f"{option[0]}: for --experiments grounded only"):
        main(["--data", str(tmp_path), "--out", str(tmp_path / "out"), *option])
