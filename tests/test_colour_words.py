"""Colour names beyond the vocabulary's own colour words (`drone_inspect_core.colour_words`): the
xkcd survey's names read as a trim colour by hue or lightness, or as none; the parser takes them only
where they stand as a colour and refuses a colour no trim is."""

from __future__ import annotations

import pytest

from controller.planning.grounding import InstructionRefused, TargetQuery, understand
from drone_inspect_core.colour_words import colour_table, colour_words, nearest_trim
from drone_inspect_core.vocabulary import parse_kinds, shipped_vocabulary


def test_the_table_reads_names_as_the_trim_their_hue_or_lightness_is() -> None:
    vocabulary = shipped_vocabulary()
    words = colour_words(vocabulary)
    assert len(colour_table()) == 949
    expected = {
        "charcoal": "black",  # greyish and dark
        "pewter": None,  # not a survey name: left to the vocabulary or a refusal
        "mustard": "yellow",
        "ochre": "yellow",
        "maroon": "red",
        "brick": "red",
        "cobalt": "blue",
        "sky blue": "blue",  # a name ending in a declared colour word is that colour
        "steel grey": "grey",
        "fire engine red": "red",
    }
    for name, colour in expected.items():
        assert words.named.get(name) == colour, name
    for name in ("green", "purple", "pink", "orange", "brown", "white", "beige", "teal"):
        assert name in words.unmatched and name not in words.named, name
    # Codes read as the colour they name (IEC 60757's two letters, work orders' three).
    assert {code: words.named.get(code) for code in ("bk", "blk", "ye", "yel", "gy", "gry", "bu", "rd")} == {
        "bk": "black", "blk": "black", "ye": "yellow", "yel": "yellow",
        "gy": "grey", "gry": "grey", "bu": "blue", "rd": "red",
    }  # fmt: skip
    assert {"gn", "grn", "wht", "og"} <= words.unmatched
    # The vocabulary's own words are never the table's to read, and the rule agrees with them where the
    # survey has the same name.
    declared = vocabulary.colour_of_word
    assert not set(declared) & set(words.named)
    survey = dict(colour_table())
    agreeing = {w: nearest_trim(vocabulary, survey[w]) for w in declared if w in survey}
    assert len(agreeing) >= 10
    assert agreeing == {w: declared[w] for w in agreeing}


def test_a_table_colour_counts_only_where_it_stands_as_a_colour() -> None:
    assert understand("Frame up the charcoal valve.") == TargetQuery("valve", "black")
    assert understand("the gauge with the mustard bezel") == TargetQuery("gauge", "yellow")
    assert understand("Put the crosshair on the navy blue breaker panel") == TargetQuery("switchbox", "blue")
    assert understand("valve, the crimson one") == TargetQuery("valve", "red")
    assert understand("valve, the mustard one") == TargetQuery("valve", "yellow")
    assert understand("the sky blue one") == TargetQuery(None, "blue")
    assert understand("Track to the mustard butterfly valve") == TargetQuery("valve", "yellow")
    assert understand("Put the crosshair on the charcoal-trimmed shutoff.") == TargetQuery("valve", "black")
    assert understand("the royal blue-trimmed pressure dial") == TargetQuery("gauge", "blue")
    assert understand("valve, the blk one") == TargetQuery("valve", "black")
    # After the noun, where a word brings the colour.
    assert understand("Have a look at the shut-off valve painted mustard.") == TargetQuery("valve", "yellow")
    assert understand("centre the steam gauge that's charcoal") == TargetQuery("gauge", "black")
    assert understand("centre the gauge in the sky") == TargetQuery("gauge", None)
    # "pale" alone is no trim's colour, but here it is part of one.
    assert understand("Look at the main valve trimmed in pale yellow.") == TargetQuery("valve", "yellow")
    # "sky" is a survey colour too, but here it is the sky: no colour asked for.
    assert understand("centre the gauge against the sky") == TargetQuery("gauge", None)
    # A survey name standing as a noun is an unknown target, refused as before the table.
    for noun in ("stone", "sky", "rust"):
        with pytest.raises(InstructionRefused, match=f"no known target is called '{noun}'"):
            understand(f"centre the {noun}")


@pytest.mark.parametrize(
    "text",
    ["the green valve", "the orange one", "the pink-trimmed valve", "the GRN tap", "the valve painted teal"],
)
def test_a_colour_no_trim_is_refused_with_the_trim_colours(text: str) -> None:
    trims = "trim colours are black, grey, red, blue, yellow"
    with pytest.raises(InstructionRefused, match=trims) as refused:
        understand(text)
    assert "\n" not in str(refused.value)


def test_industry_words_and_tags_name_their_kind() -> None:
    for text, kind in [
        ("Bring the pressure indicator into the middle.", "gauge"),
        ("centre the PG", "gauge"),
        ("line up on the shutoff", "valve"),
        ("the isolator valve", "valve"),  # "isolator" alone is a switch box; the longer phrase wins
        ("frame the distribution board", "switchbox"),
        ("the meter box", "switchbox"),
    ]:
        assert understand(text) == TargetQuery(kind, None), text
    assert understand("fly 2 meters left") == TargetQuery(None, None)  # a plural unit is no gauge


def test_a_kind_of_ones_own_takes_a_shipped_kinds_other_word_but_not_a_trained_one() -> None:
    shipped = shipped_vocabulary()
    assert "clock" in shipped.kind("gauge").other
    own = shipped.with_kinds(parse_kinds({"clock": {"words": ["clock", "wall clock"]}}))
    assert "clock" not in own.kind("gauge").other and "clock" in own.kind("clock").words
    assert understand("centre the clock", own) == TargetQuery("clock", None)
    assert understand("centre the clock") == TargetQuery("gauge", None)  # the shipped one is unchanged
    site = shipped.with_glossary({"box": "valve"})
    assert understand("centre the box", site) == TargetQuery("valve", None)
