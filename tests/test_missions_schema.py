"""Mission files: validation errors name the file and the field; random starts are seeded and in view."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from controller.missions.results import judge
from controller.missions.schema import MissionFileError, RandomStart, StartOffset, load_mission, parse_mission
from controller.missions.suite import load_suite
from controller.planning.loop_records import Outcome

MISSIONS_DIR = Path(__file__).resolve().parents[1] / "missions" / "regression"


def write(tmp_path: Path, text: str, name: str = "m.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("body", "field", "reason"),
    [
        ("name: x\nstart: {right_m: 0.2, distance_m: -1}\n", "start.distance_m", "greater than 0.5"),
        ("name: x\nmax_steps: lots\n", "max_steps", "valid integer"),
        ("name: x\nplanner: llm\n", "planner", "'latent', 'classic', 'random' or 'oracle'"),
        ("name: x\nexpect: {centered: true}\n", "expect.centered", "unknown key"),
        ("name: x\ntarget_kind: pump\n", "target_kind", "known kinds: gauge, valve, switchbox"),
        ("name: x\nvehicle: 'mavlink:14540'\n", "vehicle", "'px4-sitl' nor a MAVLink URL"),
        ("name: x\nvehicle: udp://:14540\n", "camera", "a real vehicle needs a stream URL"),
        (
            "name: x\nstart: {random: {seed: 1, view_fraction: [0.9, 0.2]}}\n",
            "start.random.view_fraction",
            "min",
        ),
        ("tags: [a]\n", "name", "Field required"),
        ("name: x\nepsilon_px: 6\nstop_margin_px: 6\n", "stop_margin_px", "smaller than epsilon_px"),
        ("name: x\nstop_margin_px: -1\n", "stop_margin_px", "greater than or equal to 0"),
        ("name: x\nloop: {max_refinements: -2}\n", "loop.max_refinements", "greater than or equal to 0"),
    ],
)
def test_a_bad_field_is_named_with_the_file(tmp_path: Path, body: str, field: str, reason: str) -> None:
    path = write(tmp_path, body)
    with pytest.raises(MissionFileError) as info:
        load_mission(path)
    assert info.value.field == field
    assert reason in info.value.reason
    assert str(path) in str(info.value) and field in str(info.value)


def test_unreadable_files_are_named(tmp_path: Path) -> None:
    with pytest.raises(MissionFileError, match="no such file"):
        load_mission(tmp_path / "missing.yaml")
    with pytest.raises(MissionFileError, match="YAML syntax error at line 3"):
        load_mission(write(tmp_path, "name: x\nstart: {right_m: [\n"))
    with pytest.raises(MissionFileError, match="expected a mapping"):
        load_mission(write(tmp_path, "- just\n- a list\n"))


def test_overrides_are_validated_like_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "name: x\nplanner: latent\n")
    assert load_mission(path, {"planner": "classic"}).planner == "classic"
    with pytest.raises(MissionFileError) as info:
        load_mission(path, {"epsilon_px": -3})
    assert info.value.field == "epsilon_px"


def test_scene_file_is_resolved_next_to_the_mission(tmp_path: Path) -> None:
    (tmp_path / "scenes").mkdir()
    path = write(tmp_path, "name: x\nscene: {config: scenes/s.yaml, seed: 4}\n")
    assert load_mission(path).scene.config == str((tmp_path / "scenes" / "s.yaml").resolve())


def test_random_start_is_seeded_and_keeps_the_target_in_view() -> None:
    spec = RandomStart(seed=11, view_fraction=(0.2, 0.8), distance_m=(1.5, 2.5), yaw_deg=(-5, 5))
    first, again, other = spec.draw(60.0, 60.0), spec.draw(60.0, 60.0), RandomStart(seed=12).draw(60.0, 60.0)
    assert first == again and first != other
    for seed in range(200):
        start = RandomStart(seed=seed, view_fraction=(0.2, 0.8), yaw_deg=(-10, 10)).draw(60.0, 45.0)
        assert isinstance(start, StartOffset)
        # Back from the pose to the image: the bearing of the target from the optical axis, then its height.
        bearing = math.atan2(-start.right_m, start.distance_m) - math.radians(start.yaw_deg)
        depth = math.hypot(start.right_m, start.distance_m) * math.cos(bearing)
        fu = math.tan(bearing) / math.tan(math.radians(30.0))
        fv = start.up_m / depth / math.tan(math.radians(22.5))
        assert 0.2 - 1e-9 <= math.hypot(fu, fv) <= 0.8 + 1e-9


def test_judge_uses_truth_over_the_detector() -> None:
    mission = parse_mission({"name": "j", "expect": {"max_steps": 5, "final_offset_px": 8}})
    # The detector says centred; truth says 14 px off: the mission fails on truth.
    failures = judge(mission, Outcome.CENTRED, 4, 10.0, (14.0, 0.0), (2.0, 1.0), has_truth=True)
    assert failures == ["final offset 14.0 px per truth > ε 10 px", "final offset 14.0 px per truth > 8 px"]
    assert judge(mission, Outcome.CENTRED, 4, 10.0, None, (2.0, 1.0), has_truth=False) == []
    assert judge(mission, Outcome.MAX_STEPS, 6, 10.0, (3.0, 3.0), None, has_truth=True) == [
        "outcome max_steps, expected centred",
        "6 steps > the expected at most 5",
    ]


def test_the_shipped_suite_is_valid_and_covers_what_ci_needs() -> None:
    missions = [m for _, m in load_suite(MISSIONS_DIR)]
    tags = {t for m in missions for t in m.tags}
    assert {"sector", "near-centre", "edge", "kind", "yaw", "distance", "wind", "hil"} <= tags
    sectors = {t for m in missions for t in m.tags if t.startswith("sector-")}
    assert len(sectors) == 8
    assert {m.target_kind for m in missions} >= {"gauge", "valve", "switchbox"}
    assert any(m.vehicle == "sim-mavlink" for m in missions)
    assert any(m.wind is not None for m in missions)
    default = load_mission(MISSIONS_DIR.parent / "default.yaml")
    assert default.vehicle == "sim" and default.planner == "latent" and default.checkpoint is None


def test_a_camera_url_with_a_simulated_vehicle_is_refused_not_ignored(tmp_path: Path) -> None:
    for vehicle in ("sim-mavlink", "px4-sitl"):
        path = write(tmp_path, f"name: x\nvehicle: {vehicle}\ncamera: http://10.0.0.2:8080/stream.mjpg\n")
        with pytest.raises(MissionFileError) as info:
            load_mission(path)
        assert info.value.field == "camera" and "streams its own camera" in info.value.reason


def test_errors_in_command_line_overrides_name_the_command_line_not_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "name: x\n")
    with pytest.raises(MissionFileError) as info:
        load_mission(path, {"epsilon_px": -2.0})
    assert info.value.field == "epsilon_px"
    assert info.value.path.startswith("command-line options over")
    broken = write(tmp_path, "name: x\nmax_steps: 0\n")
    with pytest.raises(MissionFileError) as info:
        load_mission(broken, {"epsilon_px": 5.0})
    assert info.value.path == str(broken)  # the file's own error is still the file's
