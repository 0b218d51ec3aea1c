"""Colour names an operator may use for a trim colour beyond the vocabulary's own colour words.

The vocabulary declares a few words per trim colour ("red", "crimson", "scarlet"). Operators say more
("charcoal", "mustard", "navy blue", "sky blue"); `colour_names.csv` beside this module holds the 949
names of the xkcd colour survey with their sRGB, and `colour_codes.csv` the codes people type for
colours (IEC 60757's "bk", "ye"; work orders' "blk", "grn"), each read as the colour it names.
`colour_words(vocabulary)` reads each name as one of the vocabulary's trim colours, or as a colour no
trim has:

- a declared word keeps its declared colour (the table never overrides the vocabulary);
- a name whose last word is a declared colour word is that colour ("sky blue", "steel grey",
  "fire engine red"): its head says which colour family the operator means;
- any other name is read from its sRGB in CIELAB: a colourful one is the colourful trim whose hue
  is near its own ("mustard" → yellow, "navy" → blue), a greyish one the black or grey trim nearer
  in lightness ("charcoal" → black, "steel" → grey);
- otherwise it names no trim colour (`ColourWords.unmatched`: "green" and "purple" have no trim's
  hue, "orange" has two, "white" and "beige" are no trim's). The parser refuses an instruction that
  asks for such a colour, rather than fly to whichever target of the kind is strongest.

A name made of words that also name a target or belong to an instruction's ordinary words is left
out, so a colour name never changes how the rest of an instruction reads. And a table name counts
as a colour only where it stands as one: in a noun phrase that goes on to a target's name ("the
mustard butterfly valve", "the charcoal-trimmed shutoff") or a trim's part (`TRIM_WORDS`: "the
mustard bezel", "the sky blue one"), or after a word that brings a colour (`COLOUR_LEADS`: "the valve
painted mustard"). "Centre the gauge against the sky" asks for no blue. A name
that ends in a declared colour word ("royal blue") is a colour wherever it stands, as that word is.
"""

from __future__ import annotations

import csv
import functools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from drone_inspect_core.vocabulary import Vocabulary, hex_to_rgb, normalise_phrase

COLOUR_NAMES = Path(__file__).with_name("colour_names.csv")
COLOUR_CODES = Path(__file__).with_name("colour_codes.csv")
TRIM_WORDS = frozenset(
    {"trim", "trimmed", "rim", "rimmed", "bezel", "door", "frame", "framed", "wheel", "handwheel", "handle",
     "paint", "painted", "finish", "finished", "colour", "coloured", "color", "colored", "edge", "edged",
     "ring", "lid", "cover", "surround", "one", "ones"}
)  # fmt: skip
"""Words of a trim, its paint and "one": a table's colour name before them stands as a colour ("the
valve with the mustard wheel", "the charcoal-trimmed valve")."""
COLOUR_LEADS = frozenset(
    {"painted", "coloured", "colored", "trimmed", "rimmed", "finished", "in", "is", "s", "thats", "whats"}
)
"""Words after which a table's colour name stands as a colour, after the noun ("the valve painted
mustard", "the gauge in charcoal", "the one that's ebony": "that's" is "that s" once normalised)."""
CHROMATIC = 30.0
"""CIELAB chroma from which a colour has a hue (the red, blue and yellow trims have 43-65; black and
grey about 1; beige about 25, which reads as no trim)."""
GREYISH = 12.0
"""Chroma under which a colour reads as black or grey; between this and `CHROMATIC` (beige, khaki) it
reads as no trim."""
HUE_TOLERANCE_DEG = 30.0
"""How far a name's hue may lie from a chromatic trim's: "orange" lies within it of red and of yellow
(ambiguous), "green" and "purple" of none."""
LIGHTNESS_RATIO = 1.25
"""A greyish name is the black or grey trim whose lightness is nearer, by at least this ratio (dark
grey, halfway, is neither)."""
WHITE_LIGHTNESS = 90.0
"""Greyish names lighter than this are white, which no trim is."""


@dataclass(frozen=True)
class ColourWords:
    """The colour names of the table, as the vocabulary's trim colours read them."""

    named: Mapping[str, str]
    """Phrase → trim colour name, for names the vocabulary does not declare."""
    unmatched: frozenset[str]
    """Colour names that no trim colour is (far from all, or as near to two)."""


def _lab(rgb: tuple[int, int, int]) -> np.ndarray:
    pixel = np.array([[rgb]], dtype=np.float32) / 255.0
    return cv2.cvtColor(pixel, cv2.COLOR_RGB2LAB)[0, 0].astype(np.float64)


def _csv_rows(path: Path) -> list[dict[str, str]]:
    """The rows of one of the colour tables beside this module (its `#` lines are comments)."""
    with path.open(encoding="utf-8") as handle:
        return list(csv.DictReader(line for line in handle if not line.startswith("#")))


@functools.lru_cache(maxsize=1)
def colour_table() -> tuple[tuple[str, tuple[int, int, int]], ...]:
    """(normalised name, sRGB) per row of `colour_names.csv`."""
    return tuple((normalise_phrase(row["name"]), hex_to_rgb(row["rgb"])) for row in _csv_rows(COLOUR_NAMES))


def _lch(rgb: tuple[int, int, int]) -> tuple[float, float, float]:
    lightness, a, b = _lab(rgb)
    return float(lightness), float(np.hypot(a, b)), float(np.degrees(np.arctan2(b, a)) % 360.0)


def nearest_trim(vocabulary: Vocabulary, rgb: tuple[int, int, int]) -> str | None:
    """The trim colour a colour of `rgb` reads as, None when none: by hue for a colourful one, by
    lightness for a greyish one (the constants above)."""
    lightness, chroma, hue = _lch(rgb)
    refs = _trims_lch(vocabulary)
    if chroma >= CHROMATIC:
        near = [
            name
            for name, (_, c, h) in refs.items()
            if c >= CHROMATIC and abs((hue - h + 180.0) % 360.0 - 180.0) <= HUE_TOLERANCE_DEG
        ]
        return near[0] if len(near) == 1 else None
    if chroma >= GREYISH or lightness > WHITE_LIGHTNESS:
        return None
    greys = sorted((abs(lightness - ref[0]), name) for name, ref in refs.items() if ref[1] < GREYISH)
    if not greys:
        return None
    if len(greys) > 1 and greys[1][0] < LIGHTNESS_RATIO * greys[0][0]:
        return None
    return greys[0][1]


@functools.lru_cache(maxsize=32)
def _trims_lch(vocabulary: Vocabulary) -> dict[str, tuple[float, float, float]]:
    """Each trim colour's reference as (lightness, chroma, hue), once per vocabulary."""
    return {name: _lch(colour.rgb) for name, colour in vocabulary.colours.items()}


@functools.lru_cache(maxsize=1)
def colour_codes() -> tuple[tuple[str, str], ...]:
    """(code, the colour name it stands for) per row of `colour_codes.csv`."""
    rows = _csv_rows(COLOUR_CODES)
    return tuple((normalise_phrase(row["code"]), normalise_phrase(row["name"])) for row in rows)


@functools.lru_cache(maxsize=32)
def colour_words(vocabulary: Vocabulary) -> ColourWords:
    """The table's names read against `vocabulary`'s trim colours (cached per vocabulary)."""
    declared = vocabulary.colour_of_word
    declared_single = {w: name for w, name in declared.items() if " " not in w}
    kind_words = {w for kind in vocabulary.kinds.values() for phrase in kind.words for w in phrase.split()}
    ordinary = kind_words | set(vocabulary.instruction_words)
    named: dict[str, str] = {}
    unmatched: set[str] = set()
    for phrase, rgb in colour_table():
        words = phrase.split()
        if not words or phrase in declared or any(w in ordinary for w in words):
            continue
        colour = declared_single.get(words[-1]) if len(words) > 1 else None
        if colour is None:
            colour = nearest_trim(vocabulary, rgb)
        if colour is None:
            unmatched.add(phrase)
        else:
            named[phrase] = colour
    for code, name in colour_codes():
        if code in declared or code in ordinary:
            continue
        if name in declared or name in named:
            named[code] = declared.get(name) or named[name]
        else:
            unmatched.add(code)
    return ColourWords(named=named, unmatched=frozenset(unmatched))
