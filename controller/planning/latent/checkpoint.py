"""Checkpoint folder: `model.safetensors` + `config.json` + `vocab.txt`/`tokenizer.json`.

The safetensors file holds every model tensor, the stored goal image mean
`goal_image_embedding` (d,) and `probe_distances` (2, 9): the model's own output on
a fixed, deterministic probe input, recorded at save time. Loading never executes
code (JSON + safetensors only) and checks, in order: files present, config valid,
tensor names and shapes as the config implies, the image size recorded in the
safetensors metadata against the config's, vocabulary size, and that the weights
reproduce the probe output. Every failure is
a `PlannerCheckpointError` naming the file.

`config.json`'s `planner` section (`PlannerSettings`) says how the checkpoint is flown: mirror
test-time augmentation, and the presence threshold below which the planner says the asked-for
target is not in view (written by `dronectl calibrate-presence`, which chose it on validation
scenes; `write_planner_settings` changes only that section, so the weights and their probe stand).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from pydantic import Field, ValidationError
from safetensors import SafetensorError, safe_open
from safetensors.torch import load_file, save

from controller.planning.latent.config import GOAL_PROTOTYPE_RULE, ModelConfig
from controller.planning.latent.errors import PlannerCheckpointError
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.tokenizer import VOCAB_FILE, InstructionTokenizer
from drone_inspect_core.config_files import StrictModel
from drone_inspect_core.files import write_atomic, write_json_atomic

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
FORMAT = "drone-inspect/latent-planner/1"
GOAL_KEY = "goal_image_embedding"
PROBE_KEY = "probe_distances"
PROBE_INSTRUCTIONS = ("center the gauge in the camera view.", "please center the valve.")
PROBE_TOLERANCE = 1e-3


PLANNER_KEY = "planner"
"""The section of config.json that says how the checkpoint is flown (`PlannerSettings`)."""


class PlannerSettings(StrictModel):
    """How a checkpoint is flown: config.json's `planner` section (absent: every default)."""

    mirror_tta: bool = False
    """Score each image's left-right mirror image too and add its distances, left and right swapped back."""
    presence_threshold: float | None = Field(default=None, gt=0.0, lt=1.0)
    """p(asked-for target in view) below which the planner says the target is not in view; None: the
    checkpoint was never calibrated, and its planner says nothing about presence."""
    presence_calibration: dict[str, Any] | None = None
    """Where the threshold came from (validation folders, pairs, budget, rates): a record, never read."""


@dataclass
class LoadedCheckpoint:
    model: LatentDynamicsModel  # in eval mode
    tokenizer: InstructionTokenizer
    goal_image_embedding: torch.Tensor  # (d,)
    config: ModelConfig
    meta: dict[str, Any]  # everything else in config.json (training settings, metrics, ε)

    @property
    def planner(self) -> PlannerSettings:
        """How this checkpoint is flown (checked when it was loaded)."""
        return PlannerSettings.model_validate(self.meta.get(PLANNER_KEY) or {})


def probe_input(config: ModelConfig, tokenizer: InstructionTokenizer) -> tuple[torch.Tensor, torch.Tensor]:
    """A deterministic (2, 3, S, S) seeded-noise image batch and its instruction ids."""
    s = config.image_size
    images = torch.rand(2, 3, s, s, generator=torch.Generator().manual_seed(1234))
    return images, tokenizer.batch(list(PROBE_INSTRUCTIONS))


@torch.inference_mode()
def probe_distances(
    model: LatentDynamicsModel, tokenizer: InstructionTokenizer, goal: torch.Tensor
) -> torch.Tensor:
    model.eval()
    images, ids = probe_input(model.config, tokenizer)
    return model(images, ids, goal)  # (2, 9)


def save_checkpoint(
    folder: Path,
    model: LatentDynamicsModel,
    tokenizer: InstructionTokenizer,
    goal_image_embedding: torch.Tensor,
    meta: dict[str, Any] | None = None,
) -> None:
    """Write the checkpoint folder (created if needed); `meta` goes into config.json beside the model."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    goal = goal_image_embedding.detach().reshape(-1).contiguous().float()
    tensors = {k: v.detach().contiguous() for k, v in model.state_dict().items()}
    tensors[GOAL_KEY] = goal
    tensors[PROBE_KEY] = probe_distances(model, tokenizer, goal).contiguous()
    metadata = {"format": FORMAT, "image_size": str(model.config.image_size)}
    # Each file through a temporary one and a rename: a save that fails (a full disk) leaves the last
    # whole checkpoint, never a truncated one looking whole.
    write_atomic(folder / WEIGHTS_FILE, save(tensors, metadata=metadata))
    tokenizer.save(folder)
    body = {"format": FORMAT, "model": model.config.to_dict(), "goal_prototype": GOAL_PROTOTYPE_RULE}
    body.update(meta or {})
    write_json_atomic(folder / CONFIG_FILE, body)


def load_checkpoint(folder: Path) -> LoadedCheckpoint:
    """Load and verify a checkpoint folder (see the module docstring for the checks)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise PlannerCheckpointError(f"checkpoint folder not found: {folder}")
    for name in (CONFIG_FILE, WEIGHTS_FILE, VOCAB_FILE):
        if not (folder / name).is_file():
            raise PlannerCheckpointError(f"checkpoint file missing: {folder / name}")
    config, meta = _read_config(folder / CONFIG_FILE)
    tokenizer = InstructionTokenizer.load(folder, config.max_tokens)
    if tokenizer.vocab_size != config.vocab_size:
        raise PlannerCheckpointError(
            f"{folder / VOCAB_FILE} has {tokenizer.vocab_size} tokens but {folder / CONFIG_FILE} "
            f"says vocab_size={config.vocab_size}"
        )
    weights_path = folder / WEIGHTS_FILE
    try:
        with safe_open(str(weights_path), framework="pt") as f:
            stored_size = (f.metadata() or {}).get("image_size")
        tensors = load_file(str(weights_path))
    except (SafetensorError, OSError, ValueError) as exc:
        raise PlannerCheckpointError(
            f"cannot read {weights_path}: corrupt or not a safetensors file ({exc})"
        ) from exc
    if stored_size != str(config.image_size):
        raise PlannerCheckpointError(
            f"{weights_path} was trained at image_size={stored_size} but {folder / CONFIG_FILE} says "
            f"image_size={config.image_size}"
        )
    model = LatentDynamicsModel(config)
    expected = {k: tuple(v.shape) for k, v in model.state_dict().items()}
    expected[GOAL_KEY] = (config.latent_dim,)
    expected[PROBE_KEY] = (len(PROBE_INSTRUCTIONS), 9)
    _check_shapes(tensors, expected, weights_path)
    goal, probe = tensors.pop(GOAL_KEY), tensors.pop(PROBE_KEY)
    if not all(bool(torch.isfinite(t).all()) for t in (*tensors.values(), goal)):
        raise PlannerCheckpointError(f"{weights_path} holds non-finite values (NaN or inf)")
    model.load_state_dict(tensors, strict=True)
    model.eval()
    got = probe_distances(model, tokenizer, goal)
    if not torch.allclose(got, probe, rtol=PROBE_TOLERANCE, atol=PROBE_TOLERANCE):
        raise PlannerCheckpointError(
            f"{weights_path} does not reproduce its recorded probe output at image_size="
            f"{config.image_size} (max error {float((got - probe).abs().max()):.3g}): the weights, the "
            f"vocabulary or {folder / CONFIG_FILE} were changed after saving"
        )
    return LoadedCheckpoint(model, tokenizer, goal, config, meta)


def write_planner_settings(folder: Path, settings: PlannerSettings) -> None:
    """Replace config.json's `planner` section with `settings`, leaving every other field as it is
    (written whole or not at all). The weights' probe does not depend on this section."""
    path = Path(folder) / CONFIG_FILE
    _read_config(path)  # a checkpoint config, whole, before anything is written
    body = json.loads(path.read_text())
    body[PLANNER_KEY] = settings.model_dump(mode="json", exclude_none=True)
    write_json_atomic(path, body, indent=2)


def _read_config(path: Path) -> tuple[ModelConfig, dict[str, Any]]:
    try:
        body = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PlannerCheckpointError(f"cannot parse {path}: {exc}") from exc
    if not isinstance(body, dict) or body.get("format") != FORMAT:
        raise PlannerCheckpointError(f"{path}: not a latent-planner checkpoint config (format != {FORMAT!r})")
    try:
        config = ModelConfig.from_dict(body.pop("model"))
    except (KeyError, TypeError, ValueError) as exc:
        raise PlannerCheckpointError(f"{path}: invalid 'model' section ({exc})") from exc
    try:
        PlannerSettings.model_validate(body.get(PLANNER_KEY) or {})
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise PlannerCheckpointError(
            f"{path}: invalid '{PLANNER_KEY}' section: {where}: {first['msg']}"
        ) from None
    return config, body


def _check_shapes(tensors: dict[str, torch.Tensor], expected: dict[str, tuple[int, ...]], path: Path) -> None:
    missing = sorted(set(expected) - set(tensors))
    unexpected = sorted(set(tensors) - set(expected))
    if missing or unexpected:
        raise PlannerCheckpointError(
            f"{path} does not match its config: missing tensors {missing[:5]}, unexpected {unexpected[:5]}"
        )
    for name, shape in expected.items():
        if tuple(tensors[name].shape) != shape:
            raise PlannerCheckpointError(
                f"{path}: tensor {name!r} has shape {tuple(tensors[name].shape)}, the config implies {shape}"
            )
