"""Kinds of one's own, carried by data: what a dataset or a trained model adds to the shipped vocabulary.

A kind a user adds (`kinds:` in a scene or mission file, or a kinds file given to `dronectl collect
--kinds`) travels with what is made from it, so that everything downstream knows its name and words
without being told again:

- a dataset records the kinds it holds beyond the shipped ones (`dataset.json`: `kinds` of a flown
  collection, `scene_config.kinds` of a rendered one): `dataset_kinds(meta)`;
- a detector or planner checkpoint trained on it records them in its `config.json` (`kinds`):
  `checkpoint_kinds(folder)`, read without torch, so a mission file that names the kind validates
  against the checkpoints it flies with.

Only the words travel (`words_only`): a face (the picture the rendered world draws) is a file of the
machine that collected, and a model needs none. Where several sources declare one kind name
(`merge_kinds`), they must give it the same words: otherwise it is a `KindConflictError` naming
both places (a kind given twice, differently), never a silent choice of one.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from drone_inspect_core.vocabulary import (
    VocabularyError,
    kind_mapping,
    parse_kind,
    parse_kinds,
    read_words_file,
    shipped_vocabulary,
    vocabulary_with,
)

CHECKPOINT_KINDS_FIELD = "kinds"
"""The field of a checkpoint's `config.json` (detector and planner alike) holding the kinds it added."""
_FACE_FIELDS = ("face", "image", "size_m")


class KindConflictError(VocabularyError):
    """One kind given twice with different words, or a shipped kind declared again as one's own."""


def words_only(section: Mapping[str, Any] | None) -> dict[str, dict[str, Any]]:
    """A `kinds:` section without the faces: name → {noun, train, heldout, other}, each kind parsed
    (a bad one raises `VocabularyError` naming it)."""
    out: dict[str, dict[str, Any]] = {}
    for name, data in (section or {}).items():
        bare = {k: v for k, v in data.items() if k not in _FACE_FIELDS} if isinstance(data, Mapping) else data
        out[name] = kind_mapping(parse_kind(name, bare))
    return out


def merge_kinds(sources: Iterable[tuple[str, Mapping[str, Any] | None]]) -> dict[str, dict[str, Any]]:
    """The kinds of several `(where, kinds section)` sources as one words-only section, in order of first
    appearance. Shipped kinds are left out (everyone knows them). A name two sources give different words
    is a `KindConflictError` naming both."""
    shipped = shipped_vocabulary().kind_names
    merged: dict[str, dict[str, Any]] = {}
    origin: dict[str, str] = {}
    for where, section in sources:
        try:
            kinds = words_only(section)
        except VocabularyError as exc:
            raise VocabularyError(f"{where}: {exc}") from None
        for name, data in kinds.items():
            if name in shipped:
                continue
            if name in merged and merged[name] != data:
                raise KindConflictError(
                    f"the kind {name!r} is given twice, differently: {origin[name]} says "
                    f"{_words(merged[name])}, {where} says {_words(data)}; give it one set of words"
                )
            merged.setdefault(name, data)
            origin.setdefault(name, where)
    vocabulary_with(merged)  # no phrase may name two kinds (raises VocabularyError naming the phrase)
    return merged


def _words(data: Mapping[str, Any]) -> str:
    words = (*data.get("train", ()), *data.get("heldout", ()), *data.get("other", ()))
    return "[" + ", ".join(dict.fromkeys(words)) + "]"


def own_kinds_of(names: Iterable[str], section: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """The entries of `section` (words only) for `names` that are not shipped kinds."""
    shipped = shipped_vocabulary().kind_names
    words = words_only(section)
    return {name: words[name] for name in names if name not in shipped and name in words}


def dataset_kinds(meta: Mapping[str, Any]) -> dict[str, Any]:
    """The `kinds:` section a dataset's `dataset.json` carries: a flown one's `kinds`, a rendered one's
    scene config's; {} when it adds none."""
    if isinstance(meta.get("kinds"), Mapping):
        return dict(meta["kinds"])
    scene = meta.get("scene_config")
    if isinstance(scene, Mapping) and isinstance(scene.get("kinds"), Mapping):
        return dict(scene["kinds"])
    return {}


def load_kinds_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """A kinds file: YAML with a `kinds:` section as a scene or mission file writes it (faces optional,
    images relative to the file). `VocabularyError` naming the file and the field otherwise."""
    path = Path(path)
    data = read_words_file(path, f"kinds file {path}")
    if not isinstance(data, Mapping) or set(data) != {"kinds"} or not data["kinds"]:
        raise VocabularyError(
            f"{path}: expected one section `kinds:`, e.g. `kinds: {{flange: {{words: [flange, flanges]}}}}`"
        )
    kinds = parse_kinds(data["kinds"], path.parent, f"{path}: kinds")
    return {name: kind_mapping(kind) for name, kind in kinds.items()}


def checkpoint_kinds(folder: str | Path) -> dict[str, dict[str, Any]]:
    """The kinds a detector or planner checkpoint folder added (its `config.json`'s `kinds`), words only;
    {} for a folder without them (or without a readable config: loading the model says why)."""
    path = Path(folder) / "config.json"
    try:
        stamp = path.stat().st_mtime_ns
    except OSError:
        return {}
    return _checkpoint_kinds(path, stamp)


@functools.lru_cache(maxsize=32)
def _checkpoint_kinds(path: Path, mtime_ns: int) -> dict[str, dict[str, Any]]:
    try:
        payload = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return {}
    section = payload.get(CHECKPOINT_KINDS_FIELD) if isinstance(payload, dict) else None
    try:
        return words_only(section) if isinstance(section, Mapping) else {}
    except VocabularyError as exc:
        raise VocabularyError(f"{path}: {CHECKPOINT_KINDS_FIELD}: {exc}") from None
