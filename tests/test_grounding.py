"""Grounding the instruction: the keyword parser and the choice among detections."""

from __future__ import annotations

from dataclasses import replace

import pytest

from controller.planning.grounding import (
    TargetQuery,
    describe_seen,
    parse_instruction,
    select_target,
)
from controller.training.instructions import CORPORA, builtin_templates, fill
from drone_inspect_core.vocabulary import parse_kinds, shipped_vocabulary
from perception.types import Detection


@pytest.mark.parametrize(
    ("text", "kind", "attribute"),
    [
        ("center the gauge", "gauge", None),
        ("Centre the PRESSURE GAUGE!", "gauge", None),
        ("look at the manometer", "gauge", None),
        ("put the pressure dial in the middle", "gauge", None),
        ("centre the valve", "valve", None),
        ("bring the hand-wheel to the centre", "valve", None),
        ("the shut-off valve, please", "valve", None),
        ("center the switch box", "switchbox", None),
        ("frame the electrical box", "switchbox", None),
        ("centre on the junction cabinet", "switchbox", None),
        ("centre the breaker box", "switchbox", None),
        ("center the red valve", "valve", "red"),
        ("centre the gray gauge", "gauge", "grey"),
        ("centre the grey gauge", "gauge", "grey"),
        ("centre the silver handwheel", "valve", "grey"),
        ("the gauge with the golden bezel", "gauge", "yellow"),
        ("the BLUE, switch-box", "switchbox", "blue"),
        ("the switchbox that is black", "switchbox", "black"),
        ("the blue gauge next to the red valve", "gauge", "blue"),  # the first kind; its nearest colour
        ("centre the red one", None, "red"),
        ("centre the target", None, None),
        ("fly 2 meters left", None, None),  # "meters" is not "meter": whole words, no plurals
        ("check the valves", "valve", None),  # a kind name's own plural is listed
        ("", None, None),
    ],
)
def test_parse_instruction(text: str, kind: str | None, attribute: str | None) -> None:
    assert parse_instruction(text) == TargetQuery(kind, attribute)


def test_words_inside_other_words_do_not_match() -> None:
    assert parse_instruction("the dialled number on the gaugeboard").kind is None
    assert parse_instruction("the redundant wheelbase").attribute is None
    assert parse_instruction("a reddish tap").kind == "valve"  # "tap" matches, "reddish" is no colour word


def test_every_builtin_training_and_heldout_instruction_parses_to_its_kind() -> None:
    kinds = shipped_vocabulary().kind_names
    texts = [(fill(t, k), k) for corpus in CORPORA for t in builtin_templates(corpus) for k in kinds]
    assert len(texts) > 100
    assert all(parse_instruction(text).kind == kind for text, kind in texts)


def test_a_kind_of_its_own_is_parsed_in_its_own_words_only_where_it_is_known() -> None:
    own = shipped_vocabulary().with_kinds(parse_kinds({"flange": {"words": ["pipe flange", "flange"]}}))
    assert parse_instruction("centre the red pipe flange", own) == TargetQuery("flange", "red")
    assert parse_instruction("centre the flange").kind is None  # the shipped words know no flange
    assert parse_instruction("centre the manometer", own).kind == "gauge"  # the shipped words stay


def test_query_describes_itself() -> None:
    assert TargetQuery("valve", "red").describe() == "red valve"
    assert TargetQuery(None, "red").describe() == "red target"
    assert TargetQuery().describe() == "any target"


def det(kind: str, attribute: str | None, confidence: float, u: float = 100.0) -> Detection:
    return Detection((u - 10, 90.0, u + 10, 110.0), (u, 100.0), confidence, kind, attribute)


DETECTIONS = (
    det("gauge", "blue", 0.95, 40),
    det("valve", "red", 0.7, 100),
    det("valve", "yellow", 0.8, 160),
    det("switchbox", "grey", 0.6, 200),
)


def test_select_target_by_kind_and_attribute() -> None:
    assert select_target(DETECTIONS, TargetQuery()) is DETECTIONS[0]  # strongest of any kind
    assert select_target(DETECTIONS, TargetQuery("valve")) is DETECTIONS[2]  # strongest valve
    assert select_target(DETECTIONS, TargetQuery("valve", "red")) is DETECTIONS[1]  # the red one, weaker
    assert select_target(DETECTIONS, TargetQuery(None, "grey")) is DETECTIONS[3]
    assert select_target(DETECTIONS, TargetQuery("valve", "blue")) is None  # a blue gauge is no blue valve
    assert select_target(DETECTIONS, TargetQuery("gauge", "red")) is None
    assert select_target((), TargetQuery()) is None
    unread = (det("valve", None, 0.9),)
    assert select_target(unread, TargetQuery("valve", "red")) is None  # an unread colour is not red


def test_twins_read_alike_are_told_apart_by_how_well_the_colour_fits() -> None:
    """Twins differ in their trim, so of two valves both read red one is misread: the loop takes the one
    red fits best, not the stronger detection; an unscored read comes last, equal fits go to the
    stronger, and with no colour asked the strongest is taken as before."""
    fits_worse = replace(det("valve", "red", 0.9, 60), attribute_doubt=30.0)
    fits_better = replace(det("valve", "red", 0.6, 140), attribute_doubt=8.0)
    unscored = det("valve", "red", 0.95, 100)
    red_valve = TargetQuery("valve", "red")
    assert select_target((fits_worse, fits_better), red_valve) is fits_better
    assert select_target((unscored, fits_worse, fits_better), red_valve) is fits_better
    assert select_target((unscored,), red_valve) is unscored
    assert select_target((fits_worse, fits_better), TargetQuery("valve")) is fits_worse
    as_good = replace(fits_worse, attribute_doubt=8.0)
    assert select_target((fits_better, as_good), red_valve) is as_good


def test_describe_seen() -> None:
    assert describe_seen(DETECTIONS[:1] + DETECTIONS[3:]) == "gauge (blue), switchbox (grey)"
    assert describe_seen(()) == "nothing"
    assert describe_seen((Detection((0, 0, 1, 1), (0.5, 0.5), 0.9),)) == "target"
