"""The instruction corpora: a fixed instruction, 30 training paraphrases, held-out paraphrases.

The files in `instructions/` hold one template per line with a `{target}` slot;
`{target}` becomes the spoken name of the scene's target kind ("gauge", "valve",
"switch box"). The held-out file is never read by training: it exists for the
paper's "vision + text generalisation" evaluation.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from controller.planning.latent.errors import InstructionError
from drone_inspect_core.vocabulary import shipped_vocabulary

CORPORA: tuple[str, ...] = ("fixed", "train", "heldout")
SLOT = "{target}"


def target_noun(target_kind: str) -> str:
    """The spoken name of a dataset `target_kind` (the vocabulary's noun; unknown kinds as written)."""
    return shipped_vocabulary().noun(target_kind)


def read_templates(path: Path) -> list[str]:
    """Read an instruction file: one instruction per line, blank lines and `#` comments skipped."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InstructionError(f"cannot read instruction file {path}: {exc}") from exc
    lines = [ln.strip() for ln in text.splitlines()]
    templates = [ln for ln in lines if ln and not ln.startswith("#")]
    if not templates:
        raise InstructionError(f"instruction file {path} holds no instructions")
    return templates


def builtin_templates(corpus: str) -> list[str]:
    """The shipped templates of `corpus` ("fixed", "train" or "heldout")."""
    if corpus not in CORPORA:
        raise InstructionError(f"unknown instruction corpus {corpus!r}; choose one of {CORPORA}")
    ref = resources.files("controller.training") / "instructions" / f"{corpus}.txt"
    with resources.as_file(ref) as path:
        return read_templates(Path(path))


def fill(template: str, target_kind: str) -> str:
    """One concrete instruction: the template with its `{target}` slot filled (if it has one)."""
    return template.replace(SLOT, target_noun(target_kind))


def tokenizer_corpus() -> list[str]:
    """The text the tokenizer is built from: fixed + training paraphrases for every kind.

    Held-out paraphrases are deliberately excluded so that their unseen words reach the
    model as sub-word pieces learned in training, as real unseen phrasing would.
    """
    templates = builtin_templates("fixed") + builtin_templates("train")
    return [fill(t, kind) for kind in shipped_vocabulary().kind_names for t in templates]
