"""Grounding the instruction: which of the detected targets it names.

`parse_instruction(text) -> TargetQuery` reads the target's kind and trim colour from
the words of the instruction with a fixed lexicon (below); `select_target(detections,
query)` picks the strongest detection that fits. Pure Python: no model, no torch.

Matching rules (tested in tests/test_grounding.py):

- case and punctuation are ignored ("Centre the RED, gauge!" reads as "centre the red gauge");
- whole words only: "dial" does not match "dialled", and a word's plural is not the word
  ("meters" is not "meter": "fly 2 meters left" names no gauge). Only the kind names'
  own plurals are listed (gauges, valves, switch boxes, ...);
- multi-word synonyms win over the single words inside them ("pressure gauge" is one
  mention; "switch box" is a switch box, never a "box" of something else);
- the kind is the first kind phrase in the text; its attribute is the colour word
  nearest to that phrase (before it or after it); with no kind phrase, the first colour
  word, if any, still narrows the choice ("centre the red one").

An instruction that names no known kind gives `kind=None`: the strongest detection of
any kind is the target (today's single-target behaviour).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from drone_inspect_core.targets import ATTRIBUTE_COLOURS, TARGET_KINDS
from perception.types import Detection

KIND_SYNONYMS: dict[str, tuple[str, ...]] = {
    "gauge": (
        "gauge", "gauges", "gage", "pressure gauge", "manometer", "dial", "dials", "meter",
        "pressure dial", "pressure meter", "dial gauge", "indicator dial", "barometer",
    ),
    "valve": (
        "valve", "valves", "handwheel", "handwheels", "hand wheel", "wheel", "wheels", "gate valve",
        "shut off valve", "shutoff valve", "stop valve", "ball valve", "globe valve", "tap",
        "spigot", "stopcock",
    ),
    "switchbox": (
        "switchbox", "switchboxes", "switch box", "switch boxes", "electrical box", "control box",
        "panel", "control panel", "electrical panel", "breaker box", "fuse box", "junction box",
        "junction cabinet", "cabinet", "enclosure", "isolator", "disconnect switch", "distribution box",
    ),
}  # fmt: skip
"""Every phrase that names a kind (lower case, words separated by single spaces)."""

COLOUR_WORDS: dict[str, tuple[str, ...]] = {
    "black": ("black",),
    "grey": ("grey", "gray", "silver", "silvery"),
    "red": ("red", "crimson", "scarlet"),
    "blue": ("blue", "navy"),
    "yellow": ("yellow", "gold", "golden", "amber"),
}
"""Every word that names an attribute colour (`drone_inspect_core.targets.ATTRIBUTE_COLOURS`)."""


@dataclass(frozen=True)
class TargetQuery:
    """What the instruction asks for: a kind and a trim colour, each None when not named."""

    kind: str | None = None
    attribute: str | None = None

    def __post_init__(self) -> None:
        if self.kind is not None and self.kind not in TARGET_KINDS:
            raise ValueError(f"kind must be one of {TARGET_KINDS} or None, got {self.kind!r}")
        if self.attribute is not None and self.attribute not in ATTRIBUTE_COLOURS:
            known = tuple(ATTRIBUTE_COLOURS)
            raise ValueError(f"attribute must be one of {known} or None, got {self.attribute!r}")

    def describe(self) -> str:
        """In words: "red valve", "gauge", "red target", "any target"."""
        if self.kind is None and self.attribute is None:
            return "any target"
        return " ".join(p for p in (self.attribute, self.kind or "target") if p)

    def matches(self, detection: Detection) -> bool:
        """Whether `detection` is of the asked kind and colour (an unnamed one matches anything)."""
        if self.kind is not None and detection.kind != self.kind:
            return False
        return self.attribute is None or detection.attribute == self.attribute


def _phrase_pattern(table: dict[str, tuple[str, ...]]) -> tuple[re.Pattern[str], dict[str, str]]:
    """One regex for every phrase of `table`, longest first, on word boundaries; phrase → its key."""
    owner = {phrase: key for key, phrases in table.items() for phrase in phrases}
    alternatives = sorted(owner, key=lambda p: (-len(p.split()), -len(p)))
    body = "|".join(re.escape(p).replace(r"\ ", " ") for p in alternatives)
    return re.compile(rf"(?<![a-z0-9])(?:{body})(?![a-z0-9])"), owner


_KIND_PATTERN, _KIND_OF = _phrase_pattern(KIND_SYNONYMS)
_COLOUR_PATTERN, _COLOUR_OF = _phrase_pattern(COLOUR_WORDS)


def normalise(text: str) -> str:
    """Lower case; every run of non-alphanumeric characters (punctuation, hyphens) one space."""
    return " ".join(re.sub(r"[^a-z0-9]+", " ", text.lower()).split())


def parse_instruction(text: str) -> TargetQuery:
    """The target the instruction names (see the module docstring for the rules)."""
    words = normalise(text)
    kind_match = _KIND_PATTERN.search(words)
    colours = list(_COLOUR_PATTERN.finditer(words))
    if kind_match is None:
        return TargetQuery(None, _COLOUR_OF[colours[0].group()] if colours else None)
    start, end = kind_match.span()

    def gap(colour: re.Match[str]) -> int:  # characters between the colour word and the kind phrase
        return start - colour.end() if colour.end() <= start else colour.start() - end

    attribute = _COLOUR_OF[min(colours, key=gap).group()] if colours else None
    return TargetQuery(_KIND_OF[kind_match.group()], attribute)


def select_target(detections: Iterable[Detection], query: TargetQuery) -> Detection | None:
    """The strongest detection that `query` matches; None when none does."""
    fitting = [d for d in detections if query.matches(d)]
    return max(fitting, key=lambda d: d.confidence) if fitting else None


def describe_seen(detections: Sequence[Detection]) -> str:
    """What the detector saw, for messages: "gauge (blue), switchbox (grey)", or "nothing"."""
    if not detections:
        return "nothing"
    return ", ".join(_seen(d) for d in detections)


def _seen(detection: Detection) -> str:
    name = detection.kind or "target"
    return f"{name} ({detection.attribute})" if detection.attribute else name
