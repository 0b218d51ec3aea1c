"""Grounding the instruction: which of the detected targets it names.

`parse_instruction(text, vocabulary) -> TargetQuery` reads the target's kind and trim colour from
the words of the instruction, with the words of the vocabulary (`drone_inspect_core.vocabulary`:
every phrase of a kind, every word of a colour); `select_target(detections, query)` picks the
strongest detection that fits (asked for by colour, with several read so: the one it fits best).
Pure Python: no model, no torch.

Matching rules (tested in tests/test_grounding.py):

- case and punctuation are ignored ("Centre the RED, gauge!" reads as "centre the red gauge");
- whole words only: "dial" does not match "dialled", and a word's plural is not the word
  ("meters" is not "meter": "fly 2 meters left" names no gauge). Only the kind names'
  own plurals are listed (gauges, valves, switch boxes, ...);
- multi-word synonyms win over the single words inside them ("pressure gauge" is one
  mention; "switch box" is a switch box, never a "box" of something else);
- the kind is the first kind phrase in the text; its attribute is the colour word
  nearest to that phrase (before it or after it); with no kind phrase, the first colour
  word, if any, still narrows the choice ("centre the red one");
- a colour is a declared colour word, or a colour name of the survey table that reads as a trim
  colour (`drone_inspect_core.colour_words`: "charcoal", "navy blue") where it stands as a colour
  (in a noun phrase that goes on to a target's name or a trim's part); a name that reads as no trim
  colour ("the green valve") is refused by `understand`.

An instruction that names no known kind gives `kind=None`: the strongest detection of
any kind is the target (today's single-target behaviour).
"""

from __future__ import annotations

import difflib
import functools
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol

from drone_inspect_core.colour_words import COLOUR_LEADS, TRIM_WORDS, colour_words
from drone_inspect_core.vocabulary import Vocabulary, normalise_phrase, shipped_vocabulary
from perception.types import Detection


class KindAndColour(Protocol):
    """Anything with a kind and a trim colour name: a detection, or a simulator's truth of a target."""

    @property
    def kind(self) -> str | None: ...

    @property
    def attribute(self) -> str | None: ...


@dataclass(frozen=True)
class TargetQuery:
    """What the instruction asks for: a kind and a trim colour, each None when not named.

    The names are the vocabulary's (`drone_inspect_core.vocabulary`): a kind a scene or mission added
    is as good as a shipped one; `parse_instruction` only ever gives names its vocabulary holds."""

    kind: str | None = None
    attribute: str | None = None

    def describe(self) -> str:
        """In words: "red valve", "gauge", "red target", "any target"."""
        if self.kind is None and self.attribute is None:
            return "any target"
        return " ".join(p for p in (self.attribute, self.kind or "target") if p)

    def matches(self, seen: KindAndColour) -> bool:
        """Whether `seen` (a detection, a target's truth) is of the asked kind and colour (an unnamed one
        matches anything)."""
        if self.kind is not None and seen.kind != self.kind:
            return False
        return self.attribute is None or seen.attribute == self.attribute


def _phrase_pattern(table: dict[str, tuple[str, ...]]) -> tuple[re.Pattern[str], dict[str, str]]:
    """One regex for every phrase of `table`, longest first, on word boundaries; phrase → its key."""
    owner = {phrase: key for key, phrases in table.items() for phrase in phrases}
    alternatives = sorted(owner, key=lambda p: (-len(p.split()), -len(p)))
    body = "|".join(re.escape(p).replace(r"\ ", " ") for p in alternatives)
    return re.compile(rf"(?<![a-z0-9])(?:{body})(?![a-z0-9])"), owner


Patterns = tuple[re.Pattern[str], dict[str, str], re.Pattern[str], dict[str, str]]


@functools.lru_cache(maxsize=32)
def _patterns(vocabulary: Vocabulary) -> Patterns:
    """The kind and colour patterns of a vocabulary (built once per vocabulary). A colour's phrases are
    its declared words and the colour names that read as it (`drone_inspect_core.colour_words`)."""
    kinds, kind_of = _phrase_pattern({k.name: k.words for k in vocabulary.kinds.values()})
    named = colour_words(vocabulary).named
    colours, colour_of = _phrase_pattern(
        {
            c.name: (*c.words, *(phrase for phrase, colour in named.items() if colour == c.name))
            for c in vocabulary.colours.values()
        }
    )
    return kinds, kind_of, colours, colour_of


@functools.lru_cache(maxsize=32)
def _no_trim_pattern(vocabulary: Vocabulary) -> re.Pattern[str] | None:
    """Colour names that no trim colour is ("green", "orange")."""
    unmatched = colour_words(vocabulary).unmatched
    if not unmatched:
        return None
    return _phrase_pattern({"": tuple(unmatched)})[0]


def _colour_no_trim_is(words: str, vocabulary: Vocabulary) -> str | None:
    """The first colour name in `words` that no trim is, standing in a colour's place ("the green
    valve", "the orange-trimmed one"); None when there is none."""
    pattern = _no_trim_pattern(vocabulary)
    if pattern is None:
        return None
    trims = [m.span() for m in _patterns(vocabulary)[2].finditer(words)]
    for match in pattern.finditer(words):
        if any(a <= match.start() and match.end() <= b for a, b in trims):
            continue  # a part of a trim colour's name: "pale" in "pale yellow"
        if _in_colour_place(words, match.start(), match.end(), vocabulary):
            return match.group()
    return None


def normalise(text: str) -> str:
    """Lower case; every run of non-alphanumeric characters (punctuation, hyphens) one space."""
    return normalise_phrase(text)


def parse_instruction(text: str, vocabulary: Vocabulary | None = None) -> TargetQuery:
    """The target the instruction names (see the module docstring for the rules), in the words of
    `vocabulary` (default: the shipped one)."""
    vocabulary = vocabulary or shipped_vocabulary()
    kind_pattern, kind_of, colour_pattern, colour_of = _patterns(vocabulary)
    words = normalise(text)
    kind_match = kind_pattern.search(words)
    colours = [c for c in colour_pattern.finditer(words) if _stands_as_colour(c, words, vocabulary)]
    if kind_match is None:
        return TargetQuery(None, colour_of[colours[0].group()] if colours else None)
    start, end = kind_match.span()

    def gap(colour: re.Match[str]) -> int:  # characters between the colour word and the kind phrase
        return start - colour.end() if colour.end() <= start else colour.start() - end

    attribute = colour_of[min(colours, key=gap).group()] if colours else None
    return TargetQuery(kind_of[kind_match.group()], attribute)


def _stands_as_colour(match: re.Match[str], words: str, vocabulary: Vocabulary) -> bool:
    """Whether a colour phrase found in `words` is one: a declared colour word, or a name ending in one,
    always; another colour name of the table only in a colour's place (`_in_colour_place`)."""
    phrase = match.group()
    if phrase not in colour_words(vocabulary).named or phrase.split()[-1] in vocabulary.colour_of_word:
        return True
    return _in_colour_place(words, match.start(), match.end(), vocabulary)


def _in_colour_place(words: str, start: int, end: int, vocabulary: Vocabulary) -> bool:
    """Whether the words `start:end` stand where a colour does: after a word that says a colour comes
    ("painted |mustard|", "that's |ebony|"), or before a noun phrase (the words up to the next ordinary
    word) that holds a kind phrase or starts with a trim word: "|mustard| butterfly valve",
    "|charcoal| trimmed shutoff", "|mustard| bezel", "|sky blue| one"; not "against the |sky|"
    (`colour_words` module docstring)."""
    before = words[:start].split()
    if before and before[-1] in COLOUR_LEADS:  # after the noun: "the valve painted mustard"
        return True
    following = words[end:].split()
    if following and following[0] in TRIM_WORDS:
        return True
    run = []
    for word in following:
        if word in vocabulary.instruction_words or word in DETERMINERS:
            break
        run.append(word)
    return bool(run) and _patterns(vocabulary)[0].search(" ".join(run)) is not None


SUGGEST_CUTOFF = 0.6
"""How alike (difflib's ratio) a known phrase must be to an unknown word to be offered in its place
("vavle": valve); with none that near, a refusal names the kinds instead."""
DETERMINERS = frozenset({"the", "a", "an", "that", "this", "my", "our", "your", "its"})
"""Words after which a noun stands: "the flux capacitor", "that pump"."""


class InstructionRefused(ValueError):
    """An instruction the vocabulary cannot act on; the message says which words and what is known."""


def unknown_nouns(text: str, vocabulary: Vocabulary | None = None) -> list[str]:
    """The phrases of `text` that stand where a target's name would (after a determiner, past any
    colour words) and that name no known target: ["flux capacitor"] for "centre the flux capacitor";
    [] for "centre it" or "centre the red one". A phrase made of words the vocabulary knows only as
    parts of other phrases is unknown too ("the pressure indicator": "pressure" belongs to "pressure
    gauge", "indicator" to "indicator dial"; neither names a target alone)."""
    vocabulary = vocabulary or shipped_vocabulary()
    kind_pattern, _, colour_pattern, _ = _patterns(vocabulary)
    text = normalise(text)
    words = text.split()
    colour_at = {  # the words of colours that stand as one ("the mustard one"; not "the sky")
        text[: match.start()].count(" ") + k
        for match in colour_pattern.finditer(text)
        if _stands_as_colour(match, text, vocabulary)
        for k in range(len(match.group().split()))
    }
    found: list[str] = []
    i = 0
    while i < len(words):
        if words[i] not in DETERMINERS:
            i += 1
            continue
        j = i + 1
        while j < len(words) and j in colour_at:
            j += 1  # colour words between the determiner and the noun
        run: list[str] = []
        while j < len(words) and words[j] not in vocabulary.instruction_words and words[j] not in DETERMINERS:
            run.append(words[j])
            j += 1
        if run and kind_pattern.search(" ".join(run)) is None:
            found.append(" ".join(run))
        i = max(j, i + 1)
    return found


def understand(text: str, vocabulary: Vocabulary | None = None) -> TargetQuery:
    """What the instruction asks for, or `InstructionRefused` before anything flies: an instruction that
    names no known kind but puts an unknown noun where a target's name would stand ("centre the flux
    capacitor") is refused with the word and the closest known names; "centre it" (no noun) is not.
    One that asks for a colour no trim is ("the green valve", "the orange one") is refused with the
    trim colours, rather than flown to whichever valve is strongest."""
    vocabulary = vocabulary or shipped_vocabulary()
    if not normalise(text):
        raise InstructionRefused("the instruction is empty: say what to centre, e.g. 'centre the gauge'")
    asked = _colour_no_trim_is(normalise(text), vocabulary)
    if asked is not None:
        raise InstructionRefused(
            f"{text.strip()!r}: no target's trim is {asked!r}; the trim colours are "
            f"{', '.join(vocabulary.colour_names)}"
        )
    query = parse_instruction(text, vocabulary)
    if query.kind is not None:
        return query
    unknown = unknown_nouns(text, vocabulary)
    if unknown:
        phrases = sorted({p for kind in vocabulary.kinds.values() for p in kind.words})
        word = unknown[0]
        close = difflib.get_close_matches(word, phrases, n=3, cutoff=SUGGEST_CUTOFF)
        nouns = ", ".join(vocabulary.noun(name) for name in vocabulary.kind_names)
        known = ", ".join(close) if close else f"none near it; the targets are {nouns}"
        raise InstructionRefused(
            f"{text.strip()!r}: no known target is called {word!r}; the closest known: "
            f"{known} (a site glossary can add words: `{word}: <kind>`)"
        )
    return query


def planner_instruction(query: TargetQuery, vocabulary: Vocabulary | None = None) -> str:
    """The words the latent planner hears for `query`: its kind's trained noun and its colour, in the
    planner's fixed phrase, whatever words the operator used. So the planner and the loop (which tests
    ε on `query`'s target) always agree on what was asked, and an operator's word the model never heard
    (a synonym, a site's glossary word) reaches it as one it trained on."""
    vocabulary = vocabulary or shipped_vocabulary()
    noun = vocabulary.noun(query.kind) if query.kind is not None else "target"
    return f"center the {query.attribute + ' ' if query.attribute else ''}{noun}"


def presence_query(query: TargetQuery, detection: Detection | None = None) -> TargetQuery:
    """What the loop asks the planner's presence head before it takes a detection for the target: the
    kind alone (an unnamed kind: the detection's). The head tells kinds apart (AUROC 0.98 on validation
    scenes) but not twins' trim colours (0.65; docs/targets.md), which the detector's colour reading
    judges instead."""
    kind = query.kind if query.kind is not None else (detection.kind if detection is not None else None)
    return TargetQuery(kind, None)


def select_target(detections: Iterable[Detection], query: TargetQuery) -> Detection | None:
    """The strongest detection that `query` matches; None when none does. Where `query` asks for a
    colour and several detections read it, the surest read (`attribute_doubt`; an unscored read last,
    then the strongest): twins differ in their trim, so of two read alike one is misread, and the
    misread one is mostly the less sure. On the validation folders' twin pairs read alike (`data/pval`,
    `data/pval_twins`, lossless and through the stream's JPEG; throwaway counts): with the rule reader
    the fit took the right one in 15 of 19, the confidence in 9; the learned reader (the detector's
    since 2026-11-28) read 2 pairs alike, and the doubt took the right one in both."""
    fitting = [d for d in detections if query.matches(d)]
    if not fitting:
        return None
    if query.attribute is not None and len(fitting) > 1:
        return min(fitting, key=_colour_fit_then_strength)
    return max(fitting, key=lambda d: d.confidence)


def _colour_fit_then_strength(detection: Detection) -> tuple[float, float]:
    doubt = detection.attribute_doubt
    return (math.inf if doubt is None else doubt, -detection.confidence)


def describe_seen(detections: Sequence[Detection]) -> str:
    """What the detector saw, for messages: "gauge (blue), switchbox (grey)", or "nothing"."""
    if not detections:
        return "nothing"
    return ", ".join(_seen(d) for d in detections)


def _seen(detection: Detection) -> str:
    name = detection.kind or "target"
    return f"{name} ({detection.attribute})" if detection.attribute else name
