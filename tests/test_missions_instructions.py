"""A mission's instructions: the list, the one-instruction form, per-instruction expectations, the
refusals before takeoff (in the file and on the command line), and the flight's judgement."""

from __future__ import annotations

from pathlib import Path

import pytest

from controller.missions.schema import MissionFileError, MissionInstruction, load_mission, parse_mission

DEFAULT = Path(__file__).resolve().parents[1] / "missions" / "default.yaml"


def test_one_instruction_is_a_one_element_list_and_strings_are_entries() -> None:
    one = parse_mission({"name": "m", "instruction": "centre the gauge"})
    assert one.instructions == (MissionInstruction(instruction="centre the gauge"),)
    assert parse_mission({"name": "m", "instruction": None}).instructions == ()  # resolved from the scene
    many = parse_mission(
        {
            "name": "m",
            "instructions": ["the gauge", {"instruction": "the red valve", "expect": {"max_steps": 4}}],
        }
    )
    assert [e.instruction for e in many.instructions] == ["the gauge", "the red valve"]
    assert many.instructions[0].expect is None and many.instructions[1].expect.max_steps == 4
    again = parse_mission(many.model_dump(mode="json", exclude_unset=True))  # reads back the same
    assert again.instructions == many.instructions


@pytest.mark.parametrize(
    ("fields", "field", "words"),
    [
        ({"instruction": "the gauge", "instructions": ["the valve"]}, "instruction", "not both"),
        ({"instructions": ["the gauge", "the flux capacitor"]}, "instructions[1]", "'flux capacitor'"),
        ({"instruction": "centre the flux capacitor"}, "instruction", "closest known"),
        ({"instructions": [""]}, "instructions[0].instruction", "at least 1 character"),
        (
            {"instructions": [{"instruction": "the gauge", "expect": {"centred": True}}]},
            "expect.centred",
            "unknown",
        ),
        ({"instructions": ["the gauge", "the valve"], "detector": "truth"}, "detector", "image detector"),
    ],
)
def test_bad_instructions_are_refused_naming_the_field(fields: dict, field: str, words: str) -> None:
    with pytest.raises(MissionFileError) as info:
        parse_mission({"name": "m", **fields}, "missions/m.yaml")
    assert "missions/m.yaml" in str(info.value) and field in str(info.value) and words in str(info.value)


def test_command_line_instructions_replace_the_files_one(capsys: pytest.CaptureFixture[str]) -> None:
    overrides = {"instruction": None, "instructions": ["the gauge", "the red valve"], "targets": 3}
    mission = load_mission(DEFAULT, overrides)  # the file says `instruction: center the gauge`
    assert [e.instruction for e in mission.instructions] == ["the gauge", "the red valve"]
    assert mission.targets == 3


def test_fly_refuses_an_unknown_word_and_a_bad_option_in_one_line_before_anything_flies(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from dronectl import fly_cmd

    out = tmp_path / "out"
    assert (
        fly_cmd.main(["--out", str(out), "--instruction", "the gauge", "--instruction", "the flux capacitor"])
        == 2
    )
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "instructions[1]" in error and "'flux capacitor'" in error
    assert "closest known" in error and not out.exists()  # nothing flew, no report folder
    assert fly_cmd.main(["--out", str(out), "--targets", "9"]) == 2
    error = capsys.readouterr().err.strip()
    assert "targets: Input should be less than or equal to 4" in error and not out.exists()
