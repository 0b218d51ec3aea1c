"""Operator phrasings for measuring, and what the planner hears of them in flight.

An operator-words file (`docs/operator_words.yaml` is the project's; issue 26) holds templates with
a `{target}` slot, words for each kind and for each trim colour, and colour forms ("{colour}
{word}", "{word} with the {colour} trim"). Each test image gets an instruction naming its named
target with a template and a word of its kind, and with a colour form where another target of that
kind is in view (`OperatorWords.instruction`). Nothing here trains on the file.

Two ways to score the same instructions (`dronectl evaluate --as-flown`):

- the raw text, the model alone: the model's own reading of words it may never have heard;
- as flown: each instruction through `grounding.understand` (refused: an unknown noun; misread:
  the words name another target, or none of the targets in view uniquely) and then
  `grounding.planner_instruction`, the words the planner hears in flight. An image whose
  instruction is refused or misread counts as a failure whatever the model does.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from controller.planning.grounding import InstructionRefused, TargetQuery, planner_instruction, understand
from controller.planning.latent.errors import InstructionError
from controller.training.data import TargetRef
from controller.training.pairs import named_target_name
from drone_inspect_core.vocabulary import Vocabulary, shipped_vocabulary

SLOT = "{target}"
WORD_SLOT = "{word}"
COLOUR_SLOT = "{colour}"
FIELDS = ("templates", "words", "colours", "colour_forms")

UNDERSTOOD, REFUSED, MISREAD = "understood", "refused", "misread"
"""How the loop reads an instruction (`as_flown`): the named target alone; refused; another target or
several."""


@dataclass(frozen=True)
class OperatorWords:
    """Templates, words per kind, words per colour and colour forms, as read from `path`."""

    path: Path
    templates: tuple[str, ...]
    words: Mapping[str, tuple[str, ...]]
    colours: Mapping[str, tuple[str, ...]]
    colour_forms: tuple[str, ...]

    def noun_phrase(self, name: TargetQuery, rng: np.random.Generator) -> str:
        """A word of `name`'s kind, inside a colour form when `name` has a colour."""
        words = self.words.get(name.kind or "")
        if not words:
            raise InstructionError(f"{self.path}: field 'words' has no words for kind {name.kind!r}")
        word = words[int(rng.integers(len(words)))]
        if name.attribute is None:
            return word
        colours = self.colours.get(name.attribute)
        if not colours:
            raise InstructionError(f"{self.path}: field 'colours' has no words for colour {name.attribute!r}")
        form = self.colour_forms[int(rng.integers(len(self.colour_forms)))]
        return form.replace(COLOUR_SLOT, colours[int(rng.integers(len(colours)))]).replace(WORD_SLOT, word)

    def instruction(self, name: TargetQuery, rng: np.random.Generator) -> str:
        """One instruction asking for `name`: a random template, word and (if coloured) colour form."""
        template = self.templates[int(rng.integers(len(self.templates)))]
        return template.replace(SLOT, self.noun_phrase(name, rng))

    def check_covers(self, kinds: Sequence[str]) -> None:
        """InstructionError in one line when some kind of `kinds` has no words here."""
        missing = sorted(set(kinds) - set(self.words))
        if missing:
            raise InstructionError(
                f"{self.path}: field 'words' has no words for kind {', '.join(map(repr, missing))} "
                f"(it has {', '.join(self.words) or 'none'})"
            )


def is_operator_words_file(path: str | Path) -> bool:
    """Whether `path` is a YAML file (.yaml / .yml) meant as an operator-words file."""
    return Path(path).suffix.lower() in (".yaml", ".yml")


def _strings(value: Any, where: str, slots: tuple[str, ...] = ()) -> tuple[str, ...]:
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and v.strip() for v in value):
        raise InstructionError(f"{where}: expected a non-empty list of phrases")
    for v in value:
        for slot in slots:
            if slot not in v:
                raise InstructionError(f"{where}: {v!r} has no {slot} slot")
    return tuple(v.strip() for v in value)


def _table(value: Any, where: str) -> dict[str, tuple[str, ...]]:
    if not isinstance(value, dict) or not value:
        raise InstructionError(f"{where}: expected a mapping of names to lists of words")
    return {str(k): _strings(v, f"{where}.{k}") for k, v in value.items()}


def load_operator_words(path: str | Path) -> OperatorWords:
    """Read an operator-words file; InstructionError naming the file and field on any problem."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InstructionError(f"cannot read operator-words file {path}: {reason}") from None
    if not isinstance(data, dict):
        raise InstructionError(f"{path}: expected a mapping with fields {', '.join(FIELDS)}")
    unknown = sorted(set(data) - set(FIELDS))
    if unknown:
        raise InstructionError(f"{path}: unknown field {unknown[0]!r}; the fields are {', '.join(FIELDS)}")
    if "templates" not in data or "words" not in data:
        raise InstructionError(f"{path}: fields 'templates' and 'words' are required")
    vocabulary = shipped_vocabulary()
    words = _table(data["words"], f"{path}: field 'words'")
    for kind in words:
        if kind not in vocabulary.kinds:
            raise InstructionError(
                f"{path}: field 'words': unknown kind {kind!r}; known kinds: {', '.join(vocabulary.kinds)}"
            )
    plain = {c: [c] for c in vocabulary.colour_names}
    colours = _table(data.get("colours") or plain, f"{path}: field 'colours'")
    for colour in colours:
        if colour not in vocabulary.colours:
            raise InstructionError(
                f"{path}: field 'colours': unknown colour {colour!r}; known: {', '.join(vocabulary.colours)}"
            )
    forms = data.get("colour_forms") or [f"{COLOUR_SLOT} {WORD_SLOT}"]
    return OperatorWords(
        path=path,
        templates=_strings(data["templates"], f"{path}: field 'templates'", (SLOT,)),
        words=words,
        colours=colours,
        colour_forms=_strings(forms, f"{path}: field 'colour_forms'", (COLOUR_SLOT, WORD_SLOT)),
    )


def pair_operator_words(
    targets: Sequence[tuple[TargetRef, ...]], words: OperatorWords, seed: int
) -> list[str]:
    """One instruction per image asking for its named target, its colour where another target of its
    kind is in view (seeded)."""
    words.check_covers(sorted({refs[0].kind for refs in targets}))
    rng = np.random.default_rng(seed)
    return [words.instruction(named_target_name(refs, False), rng) for refs in targets]


@dataclass(frozen=True)
class Flown:
    """What the planner hears of each instruction in flight, and how the loop read it."""

    heard: list[str]
    verdicts: list[str]
    """UNDERSTOOD, REFUSED or MISREAD per instruction."""

    def counts(self) -> dict[str, int]:
        return {v: self.verdicts.count(v) for v in (UNDERSTOOD, REFUSED, MISREAD)}


def _loop_reading(text: str, refs: Sequence[TargetRef], vocabulary: Vocabulary) -> tuple[TargetQuery, str]:
    """The query the loop would centre, and whether it names the image's named target alone."""
    try:
        query = understand(text, vocabulary)
    except InstructionRefused:
        return TargetQuery(refs[0].kind, refs[0].attribute), REFUSED
    visible = [t for t in refs if t.in_view] or [refs[0]]
    if query.kind is None and len(visible) == 1:  # "centre it": the loop centres the one detection
        query = TargetQuery(visible[0].kind, query.attribute)
    fits = [t for t in visible if t.kind == query.kind and query.attribute in (None, t.attribute)]
    named_alone = len(fits) == 1 and fits[0] is refs[0]
    return query, UNDERSTOOD if named_alone else MISREAD


def as_flown(
    texts: Sequence[str], targets: Sequence[tuple[TargetRef, ...]], vocabulary: Vocabulary | None = None
) -> Flown:
    """Each instruction as the loop flies it: understood by the parser, then in the planner's words."""
    vocabulary = vocabulary or shipped_vocabulary()
    heard, verdicts = [], []
    for text, refs in zip(texts, targets, strict=True):
        query, verdict = _loop_reading(text, refs, vocabulary)
        heard.append(planner_instruction(query, vocabulary))
        verdicts.append(verdict)
    return Flown(heard, verdicts)
