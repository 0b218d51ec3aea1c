"""Checkpoint round trip and the clear errors for missing, corrupt or mismatched checkpoints."""

import json
from pathlib import Path

import pytest
import torch
from safetensors import safe_open
from safetensors.torch import load_file, save_file

from controller.planning.latent.checkpoint import (
    CONFIG_FILE,
    WEIGHTS_FILE,
    PlannerSettings,
    load_checkpoint,
    save_checkpoint,
    write_planner_settings,
)
from controller.planning.latent.config import ModelConfig
from controller.planning.latent.errors import PlannerCheckpointError
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.tokenizer import VOCAB_FILE, InstructionTokenizer
from controller.training.instructions import tokenizer_corpus


def _tiny_checkpoint(folder: Path) -> tuple[LatentDynamicsModel, InstructionTokenizer, torch.Tensor]:
    torch.manual_seed(0)
    tok = InstructionTokenizer.train(tokenizer_corpus())
    model = LatentDynamicsModel(
        ModelConfig(
            image_size=48, base_width=8, coord_channels=True, pooling="flatten", vocab_size=tok.vocab_size
        )
    )
    model.train()
    model.image_encoder(torch.rand(8, 3, 48, 48))  # move batch-norm running statistics off their init
    goal = torch.randn(128)
    save_checkpoint(folder, model, tok, goal, {"train": {"instructions": "varied"}})
    return model.eval(), tok, goal


def _resave(path: Path, tensors: dict[str, torch.Tensor]) -> None:
    """Rewrite a weights file with edited tensors, keeping its metadata (a deliberate tamper)."""
    with safe_open(str(path), framework="pt") as f:
        metadata = f.metadata()
    save_file(tensors, str(path), metadata=metadata)


@pytest.fixture
def ckpt_dir(tmp_path: Path) -> Path:
    _tiny_checkpoint(tmp_path / "ckpt")
    return tmp_path / "ckpt"


def test_round_trip_gives_identical_outputs(tmp_path: Path) -> None:
    model, tok, goal = _tiny_checkpoint(tmp_path / "ckpt")
    loaded = load_checkpoint(tmp_path / "ckpt")
    images, ids = torch.rand(5, 3, 48, 48), tok.batch(["center the gauge"] * 4 + ["please center the valve."])
    with torch.inference_mode():
        assert torch.equal(model(images, ids, goal), loaded.model(images, ids, loaded.goal_image_embedding))
    assert loaded.config == model.config
    assert loaded.meta["train"]["instructions"] == "varied"
    assert loaded.tokenizer.ids("center the switch box") == tok.ids("center the switch box")


@pytest.mark.parametrize("name", [WEIGHTS_FILE, CONFIG_FILE, VOCAB_FILE])
def test_missing_file_is_named(ckpt_dir: Path, name: str) -> None:
    (ckpt_dir / name).unlink()
    with pytest.raises(PlannerCheckpointError, match=f"missing: .*{name}"):
        load_checkpoint(ckpt_dir)


def test_corrupt_weights_file_is_named(ckpt_dir: Path) -> None:
    data = (ckpt_dir / WEIGHTS_FILE).read_bytes()
    (ckpt_dir / WEIGHTS_FILE).write_bytes(b"\x00\x01garbage" + data[100:])
    with pytest.raises(PlannerCheckpointError, match=f"cannot read .*{WEIGHTS_FILE}"):
        load_checkpoint(ckpt_dir)


def test_tampered_tensor_shape_is_named(ckpt_dir: Path) -> None:
    tensors = load_file(str(ckpt_dir / WEIGHTS_FILE))
    tensors["fuse.weight"] = torch.zeros(128, 200)
    _resave(ckpt_dir / WEIGHTS_FILE, tensors)
    with pytest.raises(PlannerCheckpointError, match=r"'fuse.weight' has shape \(128, 200\)"):
        load_checkpoint(ckpt_dir)


def test_tampered_tensor_values_fail_the_probe(ckpt_dir: Path) -> None:
    tensors = load_file(str(ckpt_dir / WEIGHTS_FILE))
    tensors["fuse.weight"] = tensors["fuse.weight"] * 1.5
    _resave(ckpt_dir / WEIGHTS_FILE, tensors)
    with pytest.raises(PlannerCheckpointError, match="does not reproduce its recorded probe output"):
        load_checkpoint(ckpt_dir)


def test_wrong_image_size_in_config_is_caught(ckpt_dir: Path) -> None:
    body = json.loads((ckpt_dir / CONFIG_FILE).read_text())
    body["model"]["image_size"] = 96
    (ckpt_dir / CONFIG_FILE).write_text(json.dumps(body))
    with pytest.raises(
        PlannerCheckpointError, match=r"trained at image_size=48 but .*config\.json says image_size=96"
    ):
        load_checkpoint(ckpt_dir)


def test_config_that_implies_other_shapes_is_caught(ckpt_dir: Path) -> None:
    body = json.loads((ckpt_dir / CONFIG_FILE).read_text())
    body["model"]["coord_channels"] = False  # the stem would take 3 channels, the weights have 5
    (ckpt_dir / CONFIG_FILE).write_text(json.dumps(body))
    with pytest.raises(PlannerCheckpointError, match=r"image_encoder\.stem\.0\.weight"):
        load_checkpoint(ckpt_dir)


def test_bad_config_json_is_named(ckpt_dir: Path) -> None:
    (ckpt_dir / CONFIG_FILE).write_text("{not json")
    with pytest.raises(PlannerCheckpointError, match=f"cannot parse .*{CONFIG_FILE}"):
        load_checkpoint(ckpt_dir)
    (ckpt_dir / CONFIG_FILE).write_text(json.dumps({"format": "something else"}))
    with pytest.raises(PlannerCheckpointError, match="not a latent-planner checkpoint"):
        load_checkpoint(ckpt_dir)


def test_vocabulary_mismatch_is_named(ckpt_dir: Path) -> None:
    with (ckpt_dir / VOCAB_FILE).open("a") as f:
        f.write("extratoken\n")
    with pytest.raises(PlannerCheckpointError, match=f"{VOCAB_FILE} has .* tokens"):
        load_checkpoint(ckpt_dir)


def test_planner_settings_are_written_alone_and_checked_on_load(ckpt_dir: Path) -> None:
    before = json.loads((ckpt_dir / CONFIG_FILE).read_text())
    write_planner_settings(ckpt_dir, PlannerSettings(mirror_tta=True, presence_threshold=0.9))
    after = json.loads((ckpt_dir / CONFIG_FILE).read_text())
    assert after.pop("planner") == {"mirror_tta": True, "presence_threshold": 0.9}
    assert after == before  # every other field as it was
    loaded = load_checkpoint(ckpt_dir)  # the weights' probe still holds
    assert loaded.planner.presence_threshold == 0.9 and loaded.planner.mirror_tta
    (ckpt_dir / CONFIG_FILE).write_text(json.dumps({**before, "planner": {"presence_threshold": 1.5}}))
    with pytest.raises(
        PlannerCheckpointError, match=r"config.json: invalid 'planner' section: presence_threshold"
    ):
        load_checkpoint(ckpt_dir)
    (ckpt_dir / CONFIG_FILE).write_text(json.dumps({**before, "planner": {"presence_treshold": 0.5}}))
    with pytest.raises(PlannerCheckpointError, match="presence_treshold"):  # a misspelt key is not ignored
        load_checkpoint(ckpt_dir)
