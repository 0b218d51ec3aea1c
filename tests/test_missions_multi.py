"""Missions with several targets: the schema's targets/twins/target_attribute, the scene they give,
wrong-target judging, the multi-target benchmark and the not-found regression mission."""

from __future__ import annotations

from pathlib import Path

import pytest

from controller.benchmarks.missions import BenchmarkConfig, benchmark_missions, format_summary, run_benchmark
from controller.missions.results import judge, wrong_target
from controller.missions.schema import MissionFileError, load_mission, parse_mission
from controller.missions.setup import scene_config_for
from controller.planning.grounding import parse_instruction
from controller.planning.loop_records import Outcome
from drone_inspect_core.vocabulary import colour_name
from sim_world.scene.config import DEFAULT_SCENE
from sim_world.scene.sampling import sample_scene

REGRESSION = Path(__file__).resolve().parents[1] / "missions" / "regression"


@pytest.mark.parametrize(
    ("fields", "field", "words"),
    [
        ({"targets": 5}, "targets", "less than or equal to 4"),
        ({"twins": True}, "twins", "needs targets >= 2"),
        ({"targets": 2, "target_attribute": "purple"}, "target_attribute", "'purple'"),
        ({"targets": 2, "twins": True, "instruction": "center the gauge"}, "instruction", "names no colour"),
        ({"target_attribute": "red", "instruction": "center the blue gauge"}, "instruction", "names blue"),
    ],
)
def test_bad_target_fields_are_refused_naming_the_file_and_field(
    fields: dict[str, object], field: str, words: str
) -> None:
    with pytest.raises(MissionFileError) as info:
        parse_mission({"name": "m", **fields}, "missions/m.yaml")
    assert "missions/m.yaml" in str(info.value) and field in str(info.value) and words in str(info.value)


def test_scene_config_for_applies_count_twins_and_the_named_colour() -> None:
    assert scene_config_for(parse_mission({"name": "m"})) == DEFAULT_SCENE  # today's scene, untouched
    mission = parse_mission({"name": "m", "targets": 3, "twins": True, "target_attribute": "red"})
    config = scene_config_for(mission)
    assert config.target.count == (3, 3) and config.target.twins and config.target.attribute == "red"
    for seed in (1, 2, 3):
        targets = sample_scene(config, seed).targets
        assert len(targets) == 3 and colour_name(targets[0].bezel_colour) == "red"
        assert sum(t.kind == targets[0].kind for t in targets) >= 2  # the twin


def test_instruction_resolved_from_the_scene_names_the_colour_only_where_needed() -> None:
    plain = parse_mission({"name": "m", "targets": 3})
    assert plain.instruction_text("gauge", "red") == "center the gauge"
    assert plain.instruction_text("gauge", "red", kind_repeats=True) == "center the red gauge"
    twins = parse_mission({"name": "m", "targets": 2, "twins": True})
    assert twins.instruction_text("valve", "blue") == "center the blue valve"


def test_a_centring_on_another_target_is_a_wrong_target_and_never_passes() -> None:
    mission = parse_mission({"name": "m", "targets": 3})
    far, near = (40.0, -3.0), (2.0, 4.0)
    assert wrong_target(Outcome.CENTRED, 10.0, far, [far, (90.0, 0.0), near]) == 2
    assert wrong_target(Outcome.CENTRED, 10.0, near, [near, near]) is None  # the named one is centred
    assert wrong_target(Outcome.MAX_STEPS, 10.0, far, [far, near]) is None  # the loop did not stop
    assert wrong_target(Outcome.CENTRED, 10.0, far, None) is None  # no truth of the others
    failures = judge(mission, Outcome.CENTRED, 3, 10.0, far, (1.0, 1.0), True, wrong_target_index=2)
    assert failures[0].startswith("wrong target centred: target 2")


def test_multi_target_benchmark_missions_name_the_named_target_and_absent_ones_expect_not_found() -> None:
    today = benchmark_missions(BenchmarkConfig(n=3, seed=1), "classic", frozenset())
    assert all(m.instructions == () and m.targets == 1 for m in today)  # targets 1: today's missions
    config = BenchmarkConfig.of({"targets": 3, "twins": True}, n=8, seed=1, absent=0.4)
    missions = benchmark_missions(config, "classic", frozenset())
    assert missions == benchmark_missions(config, "classic", frozenset())  # the same for every run
    absent = [m for m in missions if "absent" in m.tags]
    assert 0 < len(absent) < len(missions)
    for m in missions:
        scene = sample_scene(scene_config_for(m), m.scene.seed)
        asked = parse_instruction(m.instructions[0].instruction)
        held = [(t.kind, colour_name(t.bezel_colour)) for t in scene.targets]
        if m in absent:
            assert m.expect.outcome == "target_not_found"
            assert not any(asked.kind == k and asked.attribute in (None, a) for k, a in held)
        else:
            assert (asked.kind, asked.attribute) == held[0]  # twins: the colour is always named


@pytest.mark.timeout(180)
def test_tiny_multi_target_benchmark_counts_wrong_targets_and_absent_missions() -> None:
    config = BenchmarkConfig.of({"targets": 3}, n=3, seed=1, planners=("classic", "oracle"), absent=0.34)
    summary = run_benchmark(config)
    for name in ("classic", "oracle"):
        p = summary["planners"][name]
        assert p["missions"] + p["absent"]["missions"] == 3 and p["absent"]["missions"] >= 1
        assert p["wrong_target"] == 0 and p["absent"]["not_found"] <= p["absent"]["missions"]
    assert summary["planners"]["oracle"]["successes"] == summary["planners"]["oracle"]["missions"]
    table = format_summary(summary)
    assert "wrong target" in table and "absent: not found/wandered" in table
    assert all("wrong_target" in row for row in summary["missions"])


@pytest.mark.timeout(120)
def test_not_in_view_regression_mission_ends_target_not_found_without_a_move(tmp_path: Path) -> None:
    from controller.missions.runner import run_mission

    result = run_mission(load_mission(REGRESSION / "not_in_view.yaml"), tmp_path / "report", media=False)
    assert result.passed, result.failures
    assert result.outcome == "target_not_found" and result.moves == 0 and not result.wrong_target


@pytest.mark.timeout(180)
def test_a_benchmark_in_an_operators_words_flies_what_the_loop_understands_and_counts_what_it_refuses(
    tmp_path: Path,
) -> None:
    words = tmp_path / "words.yaml"
    words.write_text(
        "templates: ['Frame up the {target}.', 'Get the {target} in the middle, please.']\n"
        "words: {gauge: [manometer], valve: [flux capacitor], switchbox: [breaker panel]}\n"
        "colours: {black: [charcoal], grey: [silver], red: [crimson], blue: [navy], yellow: [mustard]}\n"
    )
    config = BenchmarkConfig.of({"targets": 2}, n=6, seed=3, planners=("oracle",), instructions=str(words))
    missions = benchmark_missions(config, "oracle", frozenset())
    refused = [m for m in missions if "refused" in m.tags]
    flown = [m for m in missions if "refused" not in m.tags]
    assert refused and flown  # "flux capacitor" names no kind: those valve missions are refused
    assert all("flux capacitor" in m.description for m in refused)
    assert all(m.instructions[0].instruction.startswith(("Frame up the", "Get the")) for m in flown)
    summary = run_benchmark(config, report_dir=tmp_path / "reports")
    oracle = summary["planners"]["oracle"]
    assert oracle["refused"] == len(refused) and oracle["successes"] == len(flown)
    assert not summary["limits"]["reports_incomplete"]  # a refused mission still leaves its report
    assert "refused before take-off (counted as failed): oracle" in format_summary(summary)
    with pytest.raises(ValueError, match="'valve'"):  # a file without words for a kind is named up front
        words.write_text("templates: ['Frame up the {target}.']\nwords: {gauge: [manometer]}\n")
        BenchmarkConfig.of({"targets": 2}, n=1, instructions=str(words))
