"""Reading and validating YAML configuration files (scenes here, missions in `controller`).

A bad file gets one error that names the file and the field
(`scenes/x.yaml: target.size_m: min 0.5 > max 0.2`), never a traceback from deep
inside pydantic or PyYAML. Each kind of file has its own subclass of
`ConfigFileError` so callers can tell them apart.
"""

from __future__ import annotations

from collections.abc import Collection
from pathlib import Path
from typing import Annotated, Any, TypeVar

import yaml
from pydantic import AfterValidator, BaseModel, ConfigDict, ValidationError


class StrictModel(BaseModel):
    """A config model, frozen, that refuses unknown keys (a misspelt key must never be silently ignored)."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class ConfigFileError(ValueError):
    """A configuration file that cannot be used; the message names the file and the field."""

    def __init__(self, path: str | Path, field: str | None, reason: str) -> None:
        self.path = str(path)
        self.field = field
        self.reason = reason
        where = f"{self.path}: {field}" if field else self.path
        super().__init__(f"{where}: {reason}")


def check_range(value: tuple[Any, Any]) -> tuple[Any, Any]:
    """A [min, max] pair's check that min ≤ max (use as an AfterValidator)."""
    lo, hi = value
    if lo > hi:
        raise ValueError(f"min {lo:g} > max {hi:g}")
    return value


Range = Annotated[tuple[float, float], AfterValidator(check_range)]
"""A closed interval `[min, max]` (min ≤ max)."""


def field_name(loc: tuple[int | str, ...], unnamed: Collection[str] = ()) -> str:
    """Pydantic's error location as a dotted field name (`target.size_m`, `tags[1]`).

    `unnamed` lists location parts that are not fields (the tags of a union).
    """
    name = ""
    for part in loc:
        if isinstance(part, int):
            name += f"[{part}]"
        elif part in unnamed or part.startswith(("function-", "tuple[", "literal[")):
            continue
        else:
            name += f".{part}" if name else part
    return name or "(top level)"


def error_reason(error: Any) -> str:
    """One pydantic error as a short reason."""
    if error["type"] == "extra_forbidden":
        return "unknown key"
    if error["type"] in ("tuple_type", "list_type"):
        return f"expected a list, got {error['input']!r}"
    return str(error["msg"]).removeprefix("Value error, ")


M = TypeVar("M", bound=BaseModel)


def validate_mapping(
    model: type[M],
    data: object,
    source: str | Path,
    error: type[ConfigFileError],
    unnamed: Collection[str] = (),
    context: dict[str, Any] | None = None,
) -> M:
    """Validate a parsed mapping against `model`; an `error` names `source` and every bad field.

    `context` reaches the model's validators (a file's folder, for paths relative to it)."""
    if not isinstance(data, dict):
        raise error(source, None, f"expected a mapping at the top level, got {type(data).__name__}")
    try:
        return model.model_validate(data, context=context)
    except ValidationError as exc:
        # One entry per field; an error on a list that only echoes one on its items is dropped.
        problems: list[tuple[str, str]] = []
        for item in exc.errors():
            loc = tuple(item["loc"])
            field, reason = field_name(loc, unnamed), error_reason(item)
            if item["type"] == "value_error" and not loc and ": " in reason:
                field, reason = reason.split(": ", 1)  # a model-level check that names its field
            if not any(seen.startswith(field + "[") for seen, _ in problems):
                problems.append((field, reason))
        field, reason = problems[0]
        if len(problems) > 1:
            reason += " (also " + "; ".join(f"{f}: {r}" for f, r in problems[1:]) + ")"
        raise error(source, field, reason) from None


def read_yaml(path: str | Path, error: type[ConfigFileError]) -> object:
    """Parse a YAML file; a missing or unreadable file or a syntax error raises `error` naming it."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(path, None, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(path, None, f"cannot read: {exc}") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise error(path, None, f"YAML syntax error{where}: {problem}") from None
