"""Instruction words: synonyms split between training and held-out, `kind: phrase` files, training pairs."""

from pathlib import Path

import numpy as np
import pytest

from controller.evaluation.presence import auroc, judge_presence
from controller.planning.latent.errors import InstructionError
from controller.training.data import TargetRef
from controller.training.pairs import absent_names, target_name_for
from controller.training.phrasing import (
    TargetName,
    all_phrasings,
    describe,
    is_kind_phrase_file,
    read_kind_phrases,
)
from drone_inspect_core.vocabulary import shipped_vocabulary

VOCABULARY = shipped_vocabulary()


def test_held_out_synonyms_never_reach_the_training_text() -> None:
    text = " ".join(all_phrasings(["Center the {target}."], "train")).lower()
    for kind in VOCABULARY.kinds.values():
        assert not set(kind.heldout) & set(kind.train)
        for phrase in kind.heldout:
            assert phrase not in text, phrase


def test_describe_names_the_colour_only_when_asked() -> None:
    rng = np.random.default_rng(0)
    texts = {describe(TargetName("valve", "red"), ["go to the {target}"], "train", rng) for _ in range(30)}
    assert texts == {f"go to the red {s}" for s in VOCABULARY.kind("valve").train}
    plain = describe(TargetName("gauge"), ["centre the {target} now"], "heldout", rng)
    assert plain.removeprefix("centre the ").removesuffix(" now") in VOCABULARY.kind("gauge").heldout


def _ref(kind: str, colour: str, in_view: bool = True) -> TargetRef:
    return TargetRef(kind, colour, (0.0, 0.0), in_view)


def test_a_twin_in_view_forces_the_colour_and_absent_names_match_nothing() -> None:
    red, blue, box = _ref("valve", "red"), _ref("valve", "blue"), _ref("switchbox", "grey", in_view=False)
    assert target_name_for(red, [red, blue], with_colour=False) == TargetName("valve", "red")
    assert target_name_for(red, [red], with_colour=False) == TargetName("valve")
    names = absent_names([red, blue, box])
    assert TargetName("gauge") in names and TargetName("valve", "yellow") in names
    assert all(
        not any(t.kind == n.kind and n.attribute in (None, t.attribute) for t in (red, blue, box))
        for n in names
    )


def test_kind_phrase_files(tmp_path: Path) -> None:
    good = tmp_path / "phrases.txt"
    good.write_text(
        "# operators' words\ngauge: centre the manometer\nvalve: bring the handwheel to the middle\n"
    )
    assert is_kind_phrase_file(good)
    assert read_kind_phrases(good) == {
        "gauge": ["centre the manometer"],
        "valve": ["bring the handwheel to the middle"],
    }
    plain = tmp_path / "plain.txt"
    plain.write_text("Center the {target}.\n")
    assert not is_kind_phrase_file(plain)
    bad = tmp_path / "bad.txt"
    bad.write_text("gauge: fine\nturbine: centre the turbine\n")
    with pytest.raises(InstructionError, match=r"bad.txt:2: unknown target kind"):
        read_kind_phrases(bad)


def test_auroc_and_presence_judgement() -> None:
    assert auroc(np.array([0.9, 0.8]), np.array([0.1, 0.2])) == 1.0
    assert auroc(np.array([0.1]), np.array([0.9])) == 0.0
    assert auroc(np.array([0.5, 0.5]), np.array([0.5])) == 0.5
    result = judge_presence(np.array([0.9, 0.4]), np.array([0.1, 0.6, 0.2]))
    assert result.accuracy == pytest.approx(3 / 5)
    assert result.false_absent_rate == pytest.approx(0.5)
    assert result.false_present_rate == pytest.approx(1 / 3)
