"""Instruction corpora and the WordPiece tokenizer: truncation, empty input, save/load."""

import random
import subprocess
import sys
from pathlib import Path

import pytest

from controller.planning.latent.errors import InstructionError
from controller.training.instructions import builtin_templates, fill, tokenizer_corpus
from controller.planning.latent.tokenizer import InstructionTokenizer


@pytest.fixture(scope="module")
def tokenizer() -> InstructionTokenizer:
    return InstructionTokenizer.train(tokenizer_corpus(), vocab_size=5000, max_tokens=50)


def test_corpora_sizes_and_held_out_disjoint() -> None:
    train, held = builtin_templates("train"), builtin_templates("heldout")
    assert len(builtin_templates("fixed")) == 1
    assert len(train) == 30 and len(set(train)) == 30
    assert len(held) >= 30
    assert not {t.lower() for t in train} & {t.lower() for t in held}
    assert all("{target}" in t for t in train + held)
    assert fill(train[0], "switchbox") == "Center the switch box in the image."


def test_lower_cased_wordpiece_with_cls_sep(tokenizer: InstructionTokenizer) -> None:
    assert tokenizer.tokens("Center the GAUGE.") == ["[CLS]", "center", "the", "gauge", ".", "[SEP]"]
    assert tokenizer.vocab_size < 5000


def test_vocabulary_is_the_same_in_every_process_and_for_any_corpus_order(
    tokenizer: InstructionTokenizer, tmp_path: Path
) -> None:
    # Hash-ordered tie-breaking (the library's WordPieceTrainer) gave another vocabulary in some
    # processes, so a training seed did not reproduce its run.
    tokenizer.save(tmp_path)
    code = (
        "import sys; from pathlib import Path;"
        "from controller.training.instructions import tokenizer_corpus;"
        "from controller.planning.latent.tokenizer import InstructionTokenizer;"
        "InstructionTokenizer.train(tokenizer_corpus()).save(Path(sys.argv[1]))"
    )
    for run in range(2):
        other = tmp_path / f"process{run}"
        other.mkdir()
        subprocess.run([sys.executable, "-c", code, str(other)], check=True, timeout=120)
        assert (other / "vocab.txt").read_text() == (tmp_path / "vocab.txt").read_text()
    shuffled = tokenizer_corpus()
    random.Random(3).shuffle(shuffled)
    again = InstructionTokenizer.train(shuffled)
    assert again.batch(tokenizer_corpus()).tolist() == tokenizer.batch(tokenizer_corpus()).tolist()


def test_unseen_words_reuse_shared_stems_and_endings(tokenizer: InstructionTokenizer) -> None:
    assert tokenizer.tokens("centering")[1:-1] == ["center", "##ing"]
    assert tokenizer.tokens("Qz7")[1:-1] == ["q", "##z", "##7"]  # spelt from the alphabet, not [UNK]


def test_held_out_words_become_known_pieces_not_unk(tokenizer: InstructionTokenizer) -> None:
    for template in builtin_templates("heldout"):
        assert "[UNK]" not in tokenizer.tokens(fill(template, "valve")), template


def test_overlong_instruction_truncated_to_50_tokens(tokenizer: InstructionTokenizer) -> None:
    ids = tokenizer.ids("center the gauge " * 40)
    assert len(ids) == 50
    assert tokenizer.batch(["center the gauge " * 40, "center"]).shape == (2, 50)


@pytest.mark.parametrize("text", ["", "   ", "\n\t"])
def test_empty_instruction_rejected(tokenizer: InstructionTokenizer, text: str) -> None:
    with pytest.raises(InstructionError, match="instruction is empty"):
        tokenizer.ids(text)


def test_save_and_load_give_the_same_ids(tokenizer: InstructionTokenizer, tmp_path: Path) -> None:
    tokenizer.save(tmp_path)
    loaded = InstructionTokenizer.load(tmp_path)
    text = fill(builtin_templates("heldout")[3], "gauge")
    assert loaded.ids(text) == tokenizer.ids(text)
    assert loaded.vocab_size == tokenizer.vocab_size
