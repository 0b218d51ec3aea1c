"""The one vocabulary: the shipped file, kinds a user adds, and the errors a bad kind gets."""

from __future__ import annotations

from pathlib import Path

import pytest
from own_kinds import MUG, MUG_PHOTO

from controller.planning.grounding import parse_instruction
from drone_inspect_core.vocabulary import (
    UnknownKindError,
    VocabularyError,
    parse_kinds,
    shipped_vocabulary,
    vocabulary_with,
)


def test_the_shipped_vocabulary_names_three_kinds_five_colours_and_no_phrase_twice() -> None:
    vocabulary = shipped_vocabulary()
    assert vocabulary.kind_names == ("gauge", "valve", "switchbox")
    assert vocabulary.colour_names == ("black", "grey", "red", "blue", "yellow")
    seen: dict[str, str] = {}
    for kind in vocabulary.kinds.values():
        assert kind.train[0] == kind.noun and not set(kind.heldout) & set(kind.train)
        for phrase in kind.words:
            assert seen.setdefault(phrase, kind.name) == kind.name, phrase
            assert parse_instruction(f"please centre the {phrase} now").kind == kind.name, phrase
    assert vocabulary.colour_name((200, 50, 40)) == "red" and vocabulary.noun("switchbox") == "switch box"


def test_a_kind_of_ones_own_joins_the_vocabulary_and_the_parser() -> None:
    own = vocabulary_with({"mug": MUG})
    assert own.kind_names[-1] == "mug" and own.kind("mug").face.image == MUG_PHOTO.resolve()
    assert own.kind("mug").face.size_m == (0.36, 0.24)
    assert parse_instruction("centre the red coffee cup", own).kind == "mug"
    assert vocabulary_with({"mug": MUG}) is own  # built once per set of kinds
    with pytest.raises(UnknownKindError, match="known kinds: gauge, valve, switchbox, mug"):
        own.kind("flange")


@pytest.mark.parametrize(
    ("kinds", "message"),
    [
        ({"Flange!": {"words": ["flange"]}}, "lower case letters"),
        ({"flange": {"image": "missing.png", "size_m": [0.3, 0.3]}}, "no such file"),
        ({"flange": {"image": "not_an_image.png", "size_m": [0.3, 0.3]}}, "not a readable image"),
        ({"flange": {"image": str(MUG_PHOTO), "size_m": [0.3]}}, "size_m"),
        ({"flange": {"image": str(MUG_PHOTO), "size_m": [0.3, 9.0]}}, "size_m"),
        ({"flange": {"image": str(MUG_PHOTO)}}, "size_m"),
        ({"flange": {"words": ["flange"], "colour": "red"}}, "unknown field 'colour'"),
        ({"flange": {"face": {"model": "pump"}}}, "is not one of gauge, valve, switchbox"),
    ],
)
def test_a_bad_kind_is_one_line_naming_the_field(
    tmp_path: Path, kinds: dict, message: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "not_an_image.png").write_text("this is text")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(VocabularyError, match=message) as error:
        parse_kinds(kinds, tmp_path)
    assert "\n" not in str(error.value) and str(error.value).startswith("kinds.")


def test_a_phrase_may_name_only_one_kind() -> None:
    with pytest.raises(VocabularyError, match="'dial' names both 'gauge' and 'clock'"):
        shipped_vocabulary().with_kinds(parse_kinds({"clock": {"words": ["clock", "dial"]}}))
