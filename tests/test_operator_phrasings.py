"""Measuring with the operator's own phrasings (docs/operator_words.yaml): kept out of training, read
as the loop flies them (understood, then heard in the planner's words), and `dronectl evaluate` with a
file that lacks a kind ends in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from dronectl import evaluate_cmd
from latent_synthetic import write_synthetic_dataset

from controller.evaluation.operator_words import (
    MISREAD,
    REFUSED,
    UNDERSTOOD,
    as_flown,
    load_operator_words,
    pair_operator_words,
)
from controller.planning.grounding import InstructionRefused, TargetQuery, understand
from controller.planning.latent.errors import InstructionError
from controller.planning.planners import DEFAULT_CHECKPOINT
from controller.training.data import TargetRef
from controller.training.instructions import builtin_templates
from controller.training.phrasing import all_phrasings
from drone_inspect_core.vocabulary import normalise_phrase, shipped_vocabulary

REPO = Path(__file__).resolve().parents[1]
OPERATOR_WORDS = REPO / "docs" / "operator_words.yaml"


def _ref(kind: str, colour: str, in_view: bool = True) -> TargetRef:
    return TargetRef(kind, colour, (0.0, 0.0), in_view)


def test_the_operator_words_are_kept_out_of_every_training_corpus() -> None:
    words = load_operator_words(OPERATOR_WORDS)
    trained_templates = {normalise_phrase(t) for c in ("fixed", "train") for t in builtin_templates(c)}
    assert not {normalise_phrase(t) for t in words.templates} & trained_templates
    vocabulary = shipped_vocabulary()
    training_text = " ".join(all_phrasings(builtin_templates("train"), "train")).lower()
    for kind, phrases in words.words.items():
        for phrase in phrases:
            assert normalise_phrase(phrase) not in vocabulary.kind(kind).train, phrase
            assert f" {normalise_phrase(phrase)} " not in f" {normalise_phrase(training_text)} ", phrase
    assert set(words.words) == set(vocabulary.kind_names)


def test_an_instruction_names_the_colour_only_where_a_twin_is_in_view() -> None:
    words = load_operator_words(OPERATOR_WORDS)
    alone = [(_ref("valve", "red"), _ref("gauge", "red"))] * 20
    twins = [(_ref("valve", "red"), _ref("valve", "blue"))] * 20
    colour_words = {w for w in words.colours["red"]}
    assert not any(c in t for t in pair_operator_words(alone, words, 0) for c in colour_words)
    assert all(any(c in t for c in colour_words) for t in pair_operator_words(twins, words, 0))
    assert pair_operator_words(twins, words, 3) == pair_operator_words(twins, words, 3)  # seeded


def test_as_flown_the_planner_hears_its_trained_words_and_failures_are_named() -> None:
    refs = (_ref("gauge", "red"), _ref("valve", "blue"))
    twins = (_ref("valve", "red"), _ref("valve", "blue"))
    texts = [
        "Centre on the manometer.",  # an industry word the parser knows
        "Centre on the flux capacitor.",  # an unknown noun: refused
        "Frame up the gate valve.",  # twins in view, no colour: which one?
        "Frame up the crimson gate valve.",
    ]
    flown = as_flown(texts, [refs, refs, twins, twins])
    assert flown.verdicts == [UNDERSTOOD, REFUSED, MISREAD, UNDERSTOOD]
    assert flown.heard[0] == "center the gauge" and flown.heard[3] == "center the red valve"
    assert flown.counts() == {UNDERSTOOD: 2, REFUSED: 1, MISREAD: 1}


def test_a_phrase_of_known_words_that_names_no_target_is_refused() -> None:
    # "junction" belongs to "junction box" and "pressure" to "pressure gauge", but neither names a
    # target: flying to whatever is in view would be a guess.
    with pytest.raises(InstructionRefused, match="'junction pressure'"):
        understand("Bring the junction pressure into the middle of the shot.")
    assert understand("centre the red dial gauge") == TargetQuery("gauge", "red")


def test_a_file_without_words_for_a_kind_is_one_line(tmp_path: Path, capsys) -> None:
    data = write_synthetic_dataset(tmp_path / "data", n_goal=2, n_train=2, n_test=12, size=64)
    words = yaml.safe_load(OPERATOR_WORDS.read_text())
    del words["words"]["valve"]
    partial = tmp_path / "words.yaml"
    partial.write_text(yaml.safe_dump(words))
    phrases = tmp_path / "phrases.txt"
    phrases.write_text("gauge: centre the manometer\n")
    model = str(DEFAULT_CHECKPOINT)
    for instructions in (partial, phrases):
        code = evaluate_cmd.main(["--model", model, "--data", str(data), "--instructions", str(instructions)])
        err = capsys.readouterr().err.strip()
        assert code == 1 and "\n" not in err and "Traceback" not in err, err
        assert str(instructions) in err and "'valve'" in err, err
    with pytest.raises(InstructionError, match="field 'templates'"):
        words["templates"] = ["no slot here"]
        partial.write_text(yaml.safe_dump(words))
        load_operator_words(partial)


def test_evaluate_scores_the_raw_text_and_as_flown(tmp_path: Path, capsys) -> None:
    data = write_synthetic_dataset(tmp_path / "data", n_goal=2, n_train=2, n_test=12, size=64, targets=2)
    out = tmp_path / "result.json"
    argv = ["--model", str(DEFAULT_CHECKPOINT), "--data", str(data), "--instructions", str(OPERATOR_WORDS)]
    assert evaluate_cmd.main([*argv, "--as-flown", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert (
        "instructions: " + str(OPERATOR_WORDS) + " as flown" in printed and "the loop understood" in printed
    )

    results = json.loads(out.read_text())
    raw, flown = results[str(OPERATOR_WORDS)], results[f"{OPERATOR_WORDS} as flown"]
    assert sum(flown["parsed"].values()) == raw["n"] == 12
    assert np.sum(flown["correct"]) <= flown["parsed"][UNDERSTOOD]  # refused or misread never count as right
