"""The mission suite: its machinery on a small folder; the shipped regression suite with real components."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from controller.missions.suite import SuiteOptions, format_table, run_suite, write_junit

REGRESSION = Path(__file__).resolve().parents[1] / "missions" / "regression"


def write_mission(folder: Path, name: str, right_m: float, expect_steps: int) -> None:
    (folder / f"{name}.yaml").write_text(
        f"name: {name}\nscene: {{seed: 77}}\ntarget_kind: valve\n"
        f"start: {{right_m: {right_m}, up_m: 0.2, distance_m: 2.0}}\n"
        f"planner: classic\ndetector: truth\nexpect: {{max_steps: {expect_steps}}}\n"
    )


def test_suite_runs_a_folder_writes_junit_and_reports_a_failure(tmp_path: Path) -> None:
    suite_dir = tmp_path / "suite"
    suite_dir.mkdir()
    write_mission(suite_dir, "passes", right_m=0.4, expect_steps=10)
    write_mission(suite_dir, "too-strict", right_m=0.8, expect_steps=1)
    suite = run_suite(suite_dir, SuiteOptions(report_dir=tmp_path / "reports"))
    by_name = {r.name: r for r in suite.results}
    assert by_name["passes"].passed and by_name["passes"].outcome == "centred"
    assert not by_name["too-strict"].passed and by_name["too-strict"].outcome == "centred"
    assert not suite.passed
    assert (tmp_path / "reports" / "passes" / "report.json").exists()
    table = format_table(suite)
    assert "1/2 passed" in table and "too-strict" in table and "steps > the expected at most 1" in table
    write_junit(suite, tmp_path / "junit.xml")
    root = ET.parse(tmp_path / "junit.xml").getroot()
    assert root.get("tests") == "2" and root.get("failures") == "1"
    failed = [c.get("name") for c in root.iter("testcase") if c.find("failure") is not None]
    assert failed == ["too-strict"]


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_regression_suite_in_process_passes(tmp_path: Path) -> None:
    """Every in-process mission of the shipped suite, with the shipped detector and latent planner."""
    options = SuiteOptions(report_dir=tmp_path, exclude_tags=("hil",))
    suite = run_suite(REGRESSION, options)
    assert len(suite.results) >= 19
    assert suite.passed, format_table(suite)


@pytest.mark.slow
@pytest.mark.timeout(240)  # the sim-vehicle boot and every MAVSDK wait have their own timeouts inside
def test_regression_suite_hil_mission_passes(tmp_path: Path) -> None:
    """The hardware-in-the-loop mission: sim-vehicle subprocess, MAVSDK over UDP, MJPEG stream, .tlog."""
    options = SuiteOptions(report_dir=tmp_path, tags=("hil",), exclude_tags=("sequence",))
    suite = run_suite(REGRESSION, options)
    assert len(suite.results) == 1
    assert suite.passed, format_table(suite)
    report_dir = Path(suite.results[0].report_dir)
    assert (report_dir / "flight.tlog").stat().st_size > 1000
