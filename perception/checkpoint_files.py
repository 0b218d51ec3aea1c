"""Reading a perception run folder's two files, for the detector and the colour reader alike.

`config.json` is parsed as JSON and `model.safetensors` as tensors only; nothing in either is ever
executed. Every problem (missing, unreadable, another format, weights that do not match the config or
hold NaN) is raised as the caller's checkpoint error, naming the file.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file
from torch import nn

from perception.errors import DetectorCheckpointError


def read_config(
    path: Path, checkpoint_format: str, field: str, error: type[DetectorCheckpointError], writer: str
) -> dict[str, Any]:
    """The object under `field` of the config file at `path`, whose `format` must be `checkpoint_format`;
    `writer` names the command that writes such folders, for the message when the file is missing."""
    try:
        payload = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise error(path, f"missing (is this a folder written by `{writer}`?)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise error(path, f"unreadable: {exc}") from None
    if not isinstance(payload, dict) or payload.get("format") != checkpoint_format:
        got = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise error(path, f"field 'format' must be {checkpoint_format!r}, got {got!r}")
    if not isinstance(payload.get(field), dict):
        raise error(path, f"field {field!r} is missing or not an object")
    return payload[field]


def load_weights(
    model: nn.Module, path: Path, config_name: str, error: type[DetectorCheckpointError]
) -> None:
    """Load the safetensors file at `path` into `model` (strict), refusing NaN or infinite weights."""
    if not path.is_file():
        raise error(path, "missing")
    try:
        state = load_file(str(path))
    except Exception as exc:  # safetensors raises its own SafetensorError, OSError, ...
        raise error(path, f"corrupt or not a safetensors file: {exc}") from None
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()
        raise error(path, f"does not match {config_name}: {' '.join(first[:3])}") from None
    if not all(torch.isfinite(t).all() for t in state.values() if t.is_floating_point()):
        raise error(path, "holds NaN or infinite weights")
