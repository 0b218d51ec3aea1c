"""How an instruction names its target: kind synonyms and trim colours, split between training and held-out.

An instruction is a template from `instructions/*.txt` with its `{target}` slot filled by a
noun phrase for one target: a synonym of its kind, with its trim colour in front where the
colour is needed to tell it from another target of the same kind ("the red valve") and,
in training, sometimes where it is not. The synonyms are split: `train` ones are the only
ones the model (and its tokenizer) ever sees in training; `heldout` ones are new
combinations of the same words ("pressure dial", "valve wheel", "electrical panel"), so
evaluating with them measures whether the model grounds the words rather than memorises
the phrases. A word the training text never held cannot be grounded by a text encoder
trained from scratch; add such words to the training synonyms (docs/reproduce/README.md).

`kind: phrase` instruction files (`dronectl evaluate --instructions FILE`) pair each test
image with a phrase written for its named target's kind (`read_kind_phrases`).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from controller.planning.grounding import TargetQuery
from controller.planning.latent.errors import InstructionError
from drone_inspect_core.vocabulary import Vocabulary, VocabularyError, shipped_vocabulary

SLOT = "{target}"
CORPORA: tuple[str, ...] = ("fixed", "train", "heldout")
"""Word sets of the vocabulary (`drone_inspect_core.vocabulary`): `heldout` never reaches training."""

COLOURS: tuple[str, ...] = shipped_vocabulary().colour_names


def noun_phrase(name: TargetQuery, synonym: str) -> str:
    """'red valve' / 'handwheel': the colour (if any) before the synonym."""
    return f"{name.attribute} {synonym}" if name.attribute else synonym


def fill_phrase(template: str, phrase: str) -> str:
    """The template with its `{target}` slot filled (a template without a slot is returned as is)."""
    return template.replace(SLOT, phrase)


def synonyms(kind: str, corpus: str, vocabulary: Vocabulary | None = None) -> tuple[str, ...]:
    """The synonyms of `kind` in `corpus` ("fixed", "train" or "heldout") in `vocabulary` (default: the
    shipped one); an unknown kind is spoken as its name."""
    if corpus not in CORPORA:
        raise InstructionError(f"unknown synonym corpus {corpus!r}; choose one of {list(CORPORA)}")
    kind_data = (vocabulary or shipped_vocabulary()).kinds.get(kind)
    if kind_data is None:
        return (kind.replace("_", " "),)
    try:
        return kind_data.synonyms(corpus)
    except VocabularyError as exc:
        raise InstructionError(str(exc)) from None


def describe(
    name: TargetQuery,
    templates: Sequence[str],
    corpus: str,
    rng: np.random.Generator,
    vocabulary: Vocabulary | None = None,
) -> str:
    """One instruction naming `name`: a random template and a random synonym of its kind."""
    template = templates[int(rng.integers(len(templates)))]
    options = synonyms(name.kind, corpus, vocabulary)
    return fill_phrase(template, noun_phrase(name, options[int(rng.integers(len(options)))]))


PhraseKey = tuple[str, str | None, int, int]
"""(kind, colour or None, synonym index, template index) of one instruction."""


def phrasing_table(
    templates: Sequence[str], corpus: str, vocabulary: Vocabulary | None = None
) -> list[tuple[PhraseKey, str]]:
    """Every instruction of `templates` × kinds × synonyms × (no colour, each colour), with its key, for
    the kinds of `vocabulary` (default: the shipped ones; a fine-tune's adds its data's own kinds).

    The described model's tokenizer corpus, and the table its training sampler draws from."""
    vocabulary = vocabulary or shipped_vocabulary()
    out = []
    for kind in vocabulary.kind_names:
        for s, synonym in enumerate(synonyms(kind, corpus, vocabulary)):
            for attribute in (None, *COLOURS):
                phrase = noun_phrase(TargetQuery(kind, attribute), synonym)
                out.extend(
                    ((kind, attribute, s, t), fill_phrase(tpl, phrase)) for t, tpl in enumerate(templates)
                )
    return out


def all_phrasings(templates: Sequence[str], corpus: str, vocabulary: Vocabulary | None = None) -> list[str]:
    """The texts of `phrasing_table`: the tokenizer's corpus for a model trained on described targets."""
    return [text for _, text in phrasing_table(templates, corpus, vocabulary)]


_KIND_LINE = re.compile(r"^\s*([A-Za-z_ ]+?)\s*:\s*(.+?)\s*$")


def read_kind_phrases(path: Path) -> dict[str, list[str]]:
    """A `kind: phrase` file: one instruction per line for the named kind (`#` comments, blank lines skipped).

    A phrase may hold a `{target}` slot (filled with the kind's name then). Every kind must be
    a known target kind; InstructionError names the file and line otherwise.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InstructionError(f"cannot read instruction file {path}: {exc}") from exc
    phrases: dict[str, list[str]] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        match = _KIND_LINE.match(line)
        if match is None:
            raise InstructionError(f"{path}:{number}: expected 'kind: phrase', got {line.strip()!r}")
        kind = match.group(1).strip().replace(" ", "").lower()
        known = shipped_vocabulary().kind_names
        if kind not in known:
            raise InstructionError(f"{path}:{number}: unknown target kind {match.group(1)!r}; use {known}")
        phrases.setdefault(kind, []).append(match.group(2))
    if not phrases:
        raise InstructionError(f"instruction file {path} holds no 'kind: phrase' lines")
    return phrases


def is_kind_phrase_file(path: Path) -> bool:
    """Whether the first instruction line of `path` reads `kind: phrase` with a known kind."""
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return False
    for line in lines:
        if line.strip() and not line.lstrip().startswith("#"):
            match = _KIND_LINE.match(line)
            kind = match.group(1).strip().replace(" ", "").lower() if match else None
            return kind in shipped_vocabulary().kind_names
    return False
