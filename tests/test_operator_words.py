"""The operator's own words: one vocabulary for the parser and the planner, site glossaries, unknown
words refused before anything flies, and the planner hearing the words it trained on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from controller.missions.schema import MissionFileError, load_mission, parse_mission
from controller.planning.grounding import (
    InstructionRefused,
    TargetQuery,
    planner_instruction,
    understand,
    unknown_nouns,
)
from controller.planning.latent.checkpoint import load_checkpoint
from controller.planning.planners import DEFAULT_CHECKPOINT
from controller.training.instructions import CORPORA, builtin_templates
from controller.training.phrasing import all_phrasings
from drone_inspect_core.vocabulary import VocabularyError, load_glossary, shipped_vocabulary


def test_an_unknown_noun_is_refused_with_the_closest_known_words() -> None:
    with pytest.raises(InstructionRefused, match="no known target is called 'flux capacitor'") as error:
        understand("Centre the flux capacitor, please.")
    assert "closest known:" in str(error.value) and "\n" not in str(error.value)
    assert "the targets are gauge, valve, switch box" in str(error.value)  # nothing near "flux capacitor"
    with pytest.raises(InstructionRefused, match="the closest known: valve"):
        understand("centre the vavle")  # a typo is offered its word
    with pytest.raises(InstructionRefused, match="empty"):
        understand("   ")
    # No noun where a target's name would stand: nothing to refuse, the loop centres what it sees.
    assert understand("centre it") == TargetQuery()
    assert understand("centre the red one") == TargetQuery(None, "red")
    assert understand("could you please get the manometer in the middle of the view") == TargetQuery("gauge")
    assert unknown_nouns("put the pump and the blue gauge in the centre") == ["pump"]


def test_every_word_the_parser_accepts_reaches_the_planner_as_a_word_it_trained_on() -> None:
    vocabulary = shipped_vocabulary()
    training_text = " ".join(all_phrasings(builtin_templates("train"), "train")).lower()
    tokenizer = load_checkpoint(DEFAULT_CHECKPOINT).tokenizer
    for kind in vocabulary.kinds.values():
        assert kind.noun in kind.train and kind.noun in training_text
        assert "[UNK]" not in tokenizer.tokens(kind.noun)
        for phrase in kind.words:
            for colour in (None, "red"):
                said = f"centre the {colour + ' ' if colour else ''}{phrase}"
                query = understand(said)
                assert query == TargetQuery(kind.name, colour), said
                heard = planner_instruction(query)
                assert heard == f"center the {colour + ' ' if colour else ''}{kind.noun}", said
                assert heard.removeprefix("center the ") in training_text


def test_the_parser_knows_every_word_of_the_planners_templates() -> None:
    for corpus in CORPORA:
        for template in builtin_templates(corpus):
            assert unknown_nouns(template.replace("{target}", "gauge")) == [], template


def test_a_site_glossary_adds_words_for_parser_and_planner_at_once(tmp_path: Path) -> None:
    glossary = tmp_path / "site.yaml"
    glossary.write_text("pressure transmitter: gauge\nbreaker panel: switchbox\n")
    mission_file = tmp_path / "m.yaml"
    mission_file.write_text(
        yaml.safe_dump({"name": "m", "glossary": "site.yaml", "instruction": "centre the breaker panel"})
    )
    mission = load_mission(mission_file)
    assert understand("frame the pressure transmitter", mission.vocabulary) == TargetQuery("gauge")
    query = understand(mission.instructions[0].instruction, mission.vocabulary)
    assert planner_instruction(query, mission.vocabulary) == "center the switch box"
    with pytest.raises(InstructionRefused):
        understand("frame the pressure transmitter")  # without the glossary: an unknown word
    (tmp_path / "bad.yaml").write_text("pressure transmitter: pump\n")
    with pytest.raises(MissionFileError, match="glossary: unknown target kind 'pump'"):
        parse_mission({"name": "m", "glossary": str(tmp_path / "bad.yaml")})
    with pytest.raises(VocabularyError, match="no such file"):
        load_glossary(tmp_path / "missing.yaml")


def test_a_mission_whose_instruction_names_an_unknown_thing_is_refused_before_it_flies() -> None:
    with pytest.raises(MissionFileError, match="instruction: 'centre the flux capacitor': no known target"):
        parse_mission({"name": "m", "instruction": "centre the flux capacitor"})


class _Ears:
    """A fake planner for a unit test of the loop around it: it records what it heard."""

    name = "ears"

    def __init__(self) -> None:
        self.heard: list[str] = []

    def plan(self, observation):
        from controller.planning.actions import Action, XMove, ZMove
        from controller.planning.planners import Plan

        self.heard.append(observation.instruction)
        return Plan(Action(XMove.RIGHT, ZMove.NONE))


def test_the_loop_tells_the_planner_the_target_it_tests_epsilon_on_in_trained_words() -> None:
    from fake_vehicle import FakeVehicle
    from mission_fakes import FakeCamera

    from controller.planning.loop import CentringLoop
    from controller.planning.loop_records import CentringConfig
    from perception.types import Detection

    class _Detector:
        def detect_all(self, image: np.ndarray) -> list[Detection]:
            return [Detection((170, 100, 190, 120), (180.0, 110.0), 0.9, "switchbox", "red")]

    for said in ("centre the red breaker box", "centre it"):
        ears = _Ears()
        config = CentringConfig(epsilon_px=10, instruction=said, max_steps=1, settle_s=0.0)
        vehicle = FakeVehicle.at_pose(east_m=0.0, up_m=0.0)
        CentringLoop(vehicle, FakeCamera(), _Detector(), ears, config).run()
        expected = "center the red switch box" if "red" in said else "center the switch box"
        assert ears.heard == [expected], said
