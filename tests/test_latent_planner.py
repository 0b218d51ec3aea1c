"""LatentPlanner: argmin of its own distances, batch = single, bad images and instructions."""

import numpy as np
import pytest
import torch

from controller.planning.actions import Action
from controller.planning.latent.checkpoint import load_checkpoint, save_checkpoint
from controller.planning.latent.config import ModelConfig
from controller.planning.latent.errors import ImageInputError, InstructionError
from controller.training.instructions import tokenizer_corpus
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.planner import LatentPlanner
from controller.planning.latent.tokenizer import InstructionTokenizer


@pytest.fixture(scope="module")
def planner(tmp_path_factory: pytest.TempPathFactory) -> LatentPlanner:
    torch.manual_seed(3)
    folder = tmp_path_factory.mktemp("ckpt")
    tok = InstructionTokenizer.train(tokenizer_corpus())
    model = LatentDynamicsModel(ModelConfig(image_size=40, base_width=8, vocab_size=tok.vocab_size))
    for module in model.modules():  # trained-looking batch-norm statistics, so folding them matters
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.uniform_(-0.5, 0.5)
            module.running_var.uniform_(0.5, 2.0)
            torch.nn.init.uniform_(module.weight, 0.5, 1.5)
            torch.nn.init.uniform_(module.bias, -0.2, 0.2)
    save_checkpoint(folder, model, tok, torch.randn(128))
    return LatentPlanner(folder, threads=1)


def _images(n: int, size: int = 40) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    return [rng.integers(0, 256, size=(size, size, 3), dtype=np.uint8) for _ in range(n)]


def test_plan_picks_the_argmin_of_its_distances(planner: LatentPlanner) -> None:
    picked = set()
    for img in _images(12):
        action, distances = planner.plan(img, "center the gauge")
        assert isinstance(action, Action)
        assert distances.shape == (9,) and distances.dtype == np.float32
        assert action.index == int(np.argmin(distances))
        picked.add(action.index)
    assert len(picked) >= 1


def test_distances_match_the_checkpoint_model_directly(planner: LatentPlanner) -> None:
    # The planner folds batch-norm into the convolutions: the unfused checkpoint model must agree.
    ckpt = load_checkpoint(planner.checkpoint_dir)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in planner.model.image_encoder.modules())
    for img in _images(3):
        _, distances = planner.plan(img, "please center the valve.")
        x = torch.from_numpy(img).permute(2, 0, 1).unsqueeze(0).contiguous().float() / 255
        with torch.inference_mode():
            direct = ckpt.model.eval()(
                x, ckpt.tokenizer.batch(["please center the valve."]), ckpt.goal_image_embedding
            )
        np.testing.assert_allclose(distances, direct[0].numpy(), rtol=1e-4, atol=1e-5)


def test_batch_equals_single_calls(planner: LatentPlanner) -> None:
    images = _images(4)
    actions, batch = planner.plan_batch(images, "center the gauge")
    for img, action, row in zip(images, actions, batch, strict=True):
        single_action, single = planner.plan(img, "center the gauge")
        assert single_action == action
        np.testing.assert_allclose(single, row, rtol=1e-4, atol=1e-5)


def test_other_image_sizes_are_resized(planner: LatentPlanner) -> None:
    big = np.kron(_images(1)[0], np.ones((2, 2, 1), dtype=np.uint8))  # 80×80, same content
    _, d_big = planner.plan(big, "center the gauge")
    _, d_small = planner.plan(_images(1)[0], "center the gauge")
    np.testing.assert_allclose(d_big, d_small, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros((40, 40), np.uint8), "shape"),
        (np.zeros((40, 40, 4), np.uint8), "shape"),
        (np.zeros((40, 40, 3), np.float32), "uint8"),
        (np.zeros((4, 4, 3), np.uint8), "too small"),
        ([[0]], "numpy array"),
    ],
)
def test_bad_images_are_rejected(planner: LatentPlanner, image: object, message: str) -> None:
    with pytest.raises(ImageInputError, match=message):
        planner.plan(image, "center the gauge")  # type: ignore[arg-type]


def test_empty_instruction_rejected_and_long_one_truncated(planner: LatentPlanner) -> None:
    img = _images(1)[0]
    with pytest.raises(InstructionError, match="empty"):
        planner.plan(img, "  ")
    long_text = "center the gauge " + "and keep it steady " * 30
    action, distances = planner.plan(img, long_text)
    assert np.isfinite(distances).all() and action.index == int(np.argmin(distances))


def test_mirror_tta_adds_the_mirror_images_distances_left_and_right_swapped(planner: LatentPlanner) -> None:
    import json

    from controller.planning.actions import MIRRORED_INDEX

    mirrored = LatentPlanner(planner.checkpoint_dir, threads=1, mirror=True)
    assert mirrored.mirror and not planner.mirror  # off unless the checkpoint or the caller says so
    images = _images(3)
    _, plain = planner.plan_batch(images, "center the gauge")
    _, flipped = planner.plan_batch([img[:, ::-1].copy() for img in images], "center the gauge")
    actions, both = mirrored.plan_batch(images, "center the gauge")
    np.testing.assert_allclose(both, plain + flipped[:, list(MIRRORED_INDEX)], rtol=1e-4, atol=1e-5)
    assert [a.index for a in actions] == list(both.argmin(axis=1))
    # A mirror image gets the mirrored choice.
    mirror_actions, _ = mirrored.plan_batch([img[:, ::-1].copy() for img in images], "center the gauge")
    assert [a.index for a in mirror_actions] == [MIRRORED_INDEX[a.index] for a in actions]

    config = planner.checkpoint_dir / "config.json"
    body = json.loads(config.read_text())
    config.write_text(json.dumps({**body, "planner": {"mirror_tta": True}}))
    try:
        assert LatentPlanner(planner.checkpoint_dir, threads=1).mirror  # the checkpoint's own setting
        assert not LatentPlanner(planner.checkpoint_dir, threads=1, mirror=False).mirror
    finally:
        config.write_text(json.dumps(body))
