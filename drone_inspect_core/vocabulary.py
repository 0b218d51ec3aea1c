"""The one vocabulary of inspection targets: kinds, trim colours and every word for them, as data.

The shipped vocabulary is `vocabulary.yaml` beside this module; `shipped_vocabulary()` reads it
once. A scene or mission file adds kinds of its own (`kinds:`, parsed by `parse_kinds`), a site
glossary adds words (`Vocabulary.with_glossary`): both give a new `Vocabulary`, never a changed
one. Everything that needs a kind or a word asks a `Vocabulary`: the scene builds a kind's face,
the detector's checkpoint lists the kinds it knows, the instruction parser reads the words, the
planner's training text draws its phrases, mission files and the command line check kind names.

A kind's words come in three sets (see the YAML): `train` (the planner trains on them), `heldout`
(never trained: evaluation measures generalisation with them) and `other` (the parser's further
words, which the model never heard). `words` is all of them: what the parser accepts.
"""

from __future__ import annotations

import functools
import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import cv2
import yaml

BUILTIN_MODELS: tuple[str, ...] = ("gauge", "valve", "switchbox")
"""The faces the rendered world can build from geometry (`sim_world.scene.objects`)."""
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,31}$")
_SHIPPED = Path(__file__).with_name("vocabulary.yaml")


class VocabularyError(ValueError):
    """A kind, a word or a vocabulary file that cannot be used; the message names where and why."""


class UnknownKindError(VocabularyError):
    """A kind name the vocabulary does not hold; the message lists the ones it does."""


@dataclass(frozen=True)
class Face:
    """How the rendered world draws a kind: a built-in `model`, or an `image` on a panel of `size_m`."""

    model: str | None = None
    image: Path | None = None
    size_m: tuple[float, float] | None = None
    """(width, height) of the image panel, metres."""


@dataclass(frozen=True)
class TargetKind:
    """One kind of inspection target: its name, how it is spoken, its words, how it looks."""

    name: str
    noun: str
    train: tuple[str, ...]
    heldout: tuple[str, ...] = ()
    other: tuple[str, ...] = ()
    face: Face = field(default_factory=Face)

    @property
    def words(self) -> tuple[str, ...]:
        """Every phrase the parser accepts for this kind (trained, held out, and the others)."""
        return tuple(dict.fromkeys((*self.train, *self.heldout, *self.other)))

    def synonyms(self, corpus: str) -> tuple[str, ...]:
        """The phrases of one word set: "fixed" (the noun alone), "train" or "heldout"."""
        if corpus == "fixed":
            return (self.noun,)
        if corpus in ("train", "heldout"):
            return getattr(self, corpus) or (self.noun,)
        raise VocabularyError(f"unknown word set {corpus!r}; choose fixed, train or heldout")


@dataclass(frozen=True)
class AttributeColour:
    """A trim colour that tells two targets of one kind apart: its name, reference sRGB and words."""

    name: str
    rgb: tuple[int, int, int]
    words: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class Vocabulary:
    """Kinds and colours, in their declared order (the first kinds are the shipped ones), and the other
    words an instruction may hold. Compared and hashed by identity: a changed vocabulary is a new object."""

    kinds: Mapping[str, TargetKind]
    colours: Mapping[str, AttributeColour]
    instruction_words: frozenset[str] = frozenset()
    """Words that are neither targets nor colours but belong in an instruction ("centre", "the", "it")."""

    @property
    def kind_names(self) -> tuple[str, ...]:
        return tuple(self.kinds)

    @property
    def colour_names(self) -> tuple[str, ...]:
        return tuple(self.colours)

    @functools.cached_property
    def colour_of_word(self) -> Mapping[str, str]:
        """Each declared colour word ("crimson") → the name of its trim colour ("red")."""
        return {word: colour.name for colour in self.colours.values() for word in colour.words}

    def kind(self, name: str) -> TargetKind:
        """The kind called `name`; `UnknownKindError` listing the known ones otherwise."""
        try:
            return self.kinds[name]
        except KeyError:
            raise UnknownKindError(
                f"unknown target kind {name!r}; known kinds: {', '.join(self.kinds)} "
                "(a scene or mission file can add one under `kinds:`)"
            ) from None

    def check_kinds(self, names: Iterable[str]) -> tuple[str, ...]:
        """`names` as a tuple, each checked to be a known kind."""
        return tuple(self.kind(name).name for name in names)

    def noun(self, name: str) -> str:
        """How a kind is spoken ("switch box"); an unknown name as written, underscores as spaces."""
        kind = self.kinds.get(name)
        return kind.noun if kind is not None else name.replace("_", " ")

    def colour_name(self, rgb: tuple[int, int, int] | str) -> str:
        """The name of the trim colour nearest to `rgb` (an (r, g, b) tuple or '#rrggbb')."""
        if isinstance(rgb, str):
            rgb = hex_to_rgb(rgb)
        r, g, b = (float(c) for c in rgb)
        return min(
            self.colours,
            key=lambda n: sum((x - y) ** 2 for x, y in zip((r, g, b), self.colours[n].rgb, strict=True)),
        )

    def colour_hex(self, name: str) -> str:
        """'#rrggbb' of a colour name's reference."""
        return "#{:02x}{:02x}{:02x}".format(*self.colours[name].rgb)

    def with_kinds(self, kinds: Mapping[str, TargetKind]) -> Vocabulary:
        """This vocabulary and `kinds`; a kind of an existing name keeps its face and gains the words.
        A word the added kinds claim leaves another kind's `other` words (a site's "box" or "clock" is
        its own, not the shipped switch box's or gauge's); a trained or held-out word stays, and a
        claim on it is a `VocabularyError`."""
        claimed = {phrase: name for name, kind in kinds.items() for phrase in kind.words}
        merged = {
            name: replace(kind, other=tuple(p for p in kind.other if claimed.get(p, name) == name))
            for name, kind in self.kinds.items()
        }
        for name, kind in kinds.items():
            if name in merged:
                old = merged[name]
                kind = replace(old, other=tuple(dict.fromkeys((*old.other, *kind.words))))
            merged[name] = kind
        _check_words_unique(merged)
        return Vocabulary(merged, self.colours, self.instruction_words)

    def with_glossary(self, glossary: Mapping[str, str]) -> Vocabulary:
        """This vocabulary with a site's own words for its kinds (`{manometer: gauge, breaker panel:
        switchbox}`): the parser accepts them and the planner hears the kind's own trained noun."""
        extra: dict[str, TargetKind] = {}
        for phrase, kind_name in glossary.items():
            kind = self.kind(kind_name)
            words = normalise_phrase(phrase)
            if not words:
                raise VocabularyError(f"glossary: {phrase!r} holds no word")
            base = extra.get(kind.name, TargetKind(kind.name, kind.noun, ()))
            extra[kind.name] = replace(base, other=(*base.other, words))
        return self.with_kinds(extra) if extra else self


def hex_to_rgb(colour: str) -> tuple[int, int, int]:
    """'#rrggbb' to (r, g, b) in 0..255; ValueError naming the text otherwise."""
    text = colour.strip().lstrip("#")
    if not re.fullmatch(r"[0-9a-fA-F]{6}", text):
        raise ValueError(f"{colour!r} is not a colour of the form '#rrggbb'")
    return int(text[0:2], 16), int(text[2:4], 16), int(text[4:6], 16)


def normalise_phrase(text: str) -> str:
    """Lower case, every run of non-alphanumerics one space: how words are stored and matched."""
    return " ".join(re.sub(r"[^a-z0-9]+", " ", str(text).lower()).split())


def _phrases(value: Any, where: str) -> tuple[str, ...]:
    if value is None:
        return ()
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list | tuple) or not all(isinstance(v, str) for v in value):
        raise VocabularyError(f"{where}: expected a list of phrases")
    out = tuple(dict.fromkeys(p for p in (normalise_phrase(v) for v in value) if p))
    return out


def _face(value: Any, base_dir: Path | None, where: str) -> Face:
    if value is None:
        return Face()
    if not isinstance(value, Mapping):
        raise VocabularyError(f"{where}: expected {{model: NAME}} or {{image: FILE, size_m: [w, h]}}")
    unknown = set(value) - {"model", "image", "size_m"}
    if unknown:
        raise VocabularyError(f"{where}: unknown field {sorted(unknown)[0]!r}")
    model = value.get("model")
    if model is not None:
        if model not in BUILTIN_MODELS:
            raise VocabularyError(f"{where}.model: {model!r} is not one of {', '.join(BUILTIN_MODELS)}")
        if "image" in value:
            raise VocabularyError(f"{where}: give a model or an image, not both")
        return Face(model=model)
    if "image" not in value:
        raise VocabularyError(f"{where}: a face needs a model or an image")
    image = Path(str(value["image"])).expanduser()
    if not image.is_absolute() and base_dir is not None:
        image = base_dir / image
    if image.suffix.lower() not in IMAGE_SUFFIXES:
        raise VocabularyError(f"{where}.image: {image} is not a {'/'.join(IMAGE_SUFFIXES)} file")
    if not image.is_file():
        raise VocabularyError(f"{where}.image: no such file {image}")
    if not _readable_image(image.resolve(), image.stat().st_mtime_ns):
        raise VocabularyError(f"{where}.image: {image} is not a readable image")
    size = value.get("size_m")
    if (
        not isinstance(size, list | tuple)
        or len(size) != 2
        or not all(isinstance(s, int | float) and not isinstance(s, bool) for s in size)
        or not all(0.02 <= float(s) <= 3.0 for s in size)
    ):
        raise VocabularyError(
            f"{where}.size_m: expected [width, height] in metres, each 0.02..3, got {size!r}"
        )
    return Face(image=image.resolve(), size_m=(float(size[0]), float(size[1])))


@functools.lru_cache(maxsize=64)
def _readable_image(path: Path, mtime_ns: int) -> bool:
    """Whether OpenCV decodes `path` (cached per file version: scenes ask often)."""
    return cv2.imread(str(path), cv2.IMREAD_COLOR) is not None


def parse_kind(name: str, data: Any, base_dir: Path | None = None, where: str = "kinds") -> TargetKind:
    """One kind from its mapping: `noun`, `words` (or `train`/`heldout`/`other`), `face` (or `image` and
    `size_m`)."""
    here = f"{where}.{name}"
    if not isinstance(name, str) or not _NAME.match(name):
        raise VocabularyError(f"{here}: a kind's name is lower case letters, digits and _ (at most 32)")
    if not isinstance(data, Mapping):
        raise VocabularyError(f"{here}: expected a mapping")
    allowed = {"noun", "words", "train", "heldout", "other", "face", "image", "size_m"}
    unknown = set(data) - allowed
    if unknown:
        raise VocabularyError(
            f"{here}: unknown field {sorted(unknown)[0]!r} (known: {', '.join(sorted(allowed))})"
        )
    noun = normalise_phrase(data.get("noun") or name.replace("_", " "))
    train = _phrases(data.get("train"), f"{here}.train") or _phrases(data.get("words"), f"{here}.words")
    if "words" in data and "train" in data:
        raise VocabularyError(f"{here}: give `words` or `train`, not both")
    train = tuple(dict.fromkeys((noun, *train)))
    face_data = data.get("face")
    if "image" in data or "size_m" in data:
        if face_data is not None:
            raise VocabularyError(f"{here}: give `face` or `image` + `size_m`, not both")
        face_data = {"image": data.get("image"), "size_m": data.get("size_m")}
    return TargetKind(
        name=name,
        noun=noun,
        train=train,
        heldout=_phrases(data.get("heldout"), f"{here}.heldout"),
        other=_phrases(data.get("other"), f"{here}.other"),
        face=_face(face_data, base_dir, f"{here}.face"),
    )


def parse_kinds(data: Any, base_dir: Path | None = None, where: str = "kinds") -> dict[str, TargetKind]:
    """A `kinds:` section (name → kind mapping); `VocabularyError` naming the field otherwise."""
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise VocabularyError(f"{where}: expected a mapping of kind names to kinds")
    return {name: parse_kind(name, value, base_dir, where) for name, value in data.items()}


def _check_words_unique(kinds: Mapping[str, TargetKind]) -> None:
    """No phrase may name two kinds: the parser could not tell which is meant."""
    owner: dict[str, str] = {}
    for kind in kinds.values():
        for phrase in kind.words:
            if owner.setdefault(phrase, kind.name) != kind.name:
                raise VocabularyError(f"the phrase {phrase!r} names both {owner[phrase]!r} and {kind.name!r}")


def parse_vocabulary(data: Any, base_dir: Path | None = None, source: str = "vocabulary") -> Vocabulary:
    """A whole vocabulary mapping (`kinds:` and `colours:`)."""
    if not isinstance(data, Mapping) or set(data) - {"kinds", "colours", "instruction_words"}:
        raise VocabularyError(f"{source}: expected the sections `kinds`, `colours` and `instruction_words`")
    kinds = parse_kinds(data.get("kinds"), base_dir, f"{source}: kinds")
    if not kinds:
        raise VocabularyError(f"{source}: no kinds")
    _check_words_unique(kinds)
    extras = _phrases(data.get("instruction_words"), f"{source}: instruction_words")
    colours: dict[str, AttributeColour] = {}
    for name, value in (data.get("colours") or {}).items():
        where = f"{source}: colours.{name}"
        if not isinstance(value, Mapping) or "rgb" not in value:
            raise VocabularyError(f"{where}: expected {{rgb: '#rrggbb', words: [...]}}")
        try:
            rgb = hex_to_rgb(str(value["rgb"]))
        except ValueError as exc:
            raise VocabularyError(f"{where}.rgb: {exc}") from None
        words = _phrases(value.get("words"), f"{where}.words") or (name,)
        colours[name] = AttributeColour(name, rgb, words)
    if not colours:
        raise VocabularyError(f"{source}: no colours")
    return Vocabulary(kinds, colours, frozenset(extras))


@functools.cache
def shipped_vocabulary() -> Vocabulary:
    """The vocabulary the project ships (`vocabulary.yaml`), read once."""
    data = yaml.safe_load(_SHIPPED.read_text(encoding="utf-8"))
    return parse_vocabulary(data, _SHIPPED.parent, str(_SHIPPED))


def colour_name(rgb: tuple[int, int, int] | str) -> str:
    """The name of the shipped trim colour nearest to `rgb` (colours are the same for every scene)."""
    return shipped_vocabulary().colour_name(rgb)


def kind_mapping(kind: TargetKind) -> dict[str, Any]:
    """A kind as the mapping `parse_kind` reads (the image path absolute): how it travels in JSON."""
    face: dict[str, Any]
    if kind.face.image is not None:
        face = {"image": str(kind.face.image), "size_m": list(kind.face.size_m or ())}
    else:
        face = {"model": kind.face.model} if kind.face.model else {}
    data: dict[str, Any] = {"noun": kind.noun, "train": list(kind.train)}
    if kind.heldout:
        data["heldout"] = list(kind.heldout)
    if kind.other:
        data["other"] = list(kind.other)
    if face:
        data["face"] = face
    return data


def validated_kinds(value: Any, base_dir: Path | None, where: str = "kinds") -> dict[str, dict[str, Any]]:
    """A `kinds:` field of a config model, checked (images readable, no phrase naming two kinds) and
    returned as plain data with absolute image paths, so that it survives a JSON round trip.
    Raises ValueError with the field inside the section named (for pydantic validators)."""
    try:
        kinds = parse_kinds(value, base_dir, where)
        shipped_vocabulary().with_kinds(kinds)
    except VocabularyError as exc:
        raise ValueError(str(exc).removeprefix(where + ".")) from None
    return {name: kind_mapping(kind) for name, kind in kinds.items()}


def vocabulary_with(*kinds: Mapping[str, Any]) -> Vocabulary:
    """The shipped vocabulary with the `kinds:` sections given (as `validated_kinds` stores them), in order;
    the same sections give the same object (cached: scenes ask for it per target they draw)."""
    key = json.dumps([dict(k) for k in kinds], sort_keys=True)
    return _vocabulary_with(key)


@functools.lru_cache(maxsize=64)
def _vocabulary_with(key: str) -> Vocabulary:
    vocabulary = shipped_vocabulary()
    for section in json.loads(key):
        vocabulary = vocabulary.with_kinds(parse_kinds(section))
    return vocabulary


def read_words_file(path: Path, name: str) -> Any:
    """The YAML contents of a glossary or kinds file; `VocabularyError` starting with `name` when it is
    missing or unreadable."""
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise VocabularyError(f"{name}: no such file") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise VocabularyError(f"{name}: cannot read it: {str(exc).splitlines()[0]}") from None


def load_glossary(path: str | Path) -> dict[str, str]:
    """A site glossary file: YAML `phrase: kind` lines (`manometer: gauge`); `VocabularyError` naming the
    file and the line's phrase otherwise (the kinds are checked when the glossary joins a vocabulary)."""
    path = Path(path)
    data = read_words_file(path, f"glossary {path}")
    if not isinstance(data, Mapping) or not data:
        raise VocabularyError(f"glossary {path}: expected `phrase: kind` lines, e.g. `manometer: gauge`")
    bad = [str(k) for k, v in data.items() if not isinstance(k, str) or not isinstance(v, str)]
    if bad:
        raise VocabularyError(f"glossary {path}: {bad[0]!r}: expected `phrase: kind`")
    return {str(k): str(v) for k, v in data.items()}
