"""Training on a tiny SYNTHETIC fixture dataset beats chance by a wide margin (and quickly)."""

from pathlib import Path

import pytest
import torch
from latent_synthetic import small_grounded, write_synthetic_dataset

from controller.evaluation.evaluate import evaluate_checkpoint
from controller.planning.latent.config import ModelConfig
from controller.training.config import AugmentConfig, LossWeights, TrainConfig
from controller.training.data import load_images, load_index
from controller.training.train import CURVES_FILE, METRICS_FILE, train


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_synthetic_dataset(tmp_path_factory.mktemp("synthetic"), n_train=240, n_test=120, size=64)


# The paper's head and augmentation, and the cpu preset's: flattened head, label-exact translation
# (labels recomputed every step) and the preset's loss weights.
VARIANTS = {
    "paper-head": ("gap", AugmentConfig(shear_deg=0.0), LossWeights()),
    "cpu-preset-style": ("flatten", AugmentConfig(translate=0.25), LossWeights(cons=0.1, reg=0.01)),
}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_training_beats_chance_on_held_out_images(synthetic: Path, tmp_path: Path, variant: str) -> None:
    pooling, augment, weights = VARIANTS[variant]
    model_cfg = ModelConfig(image_size=64, base_width=8, coord_channels=True, pooling=pooling)
    # Settings that converge in ~10 CPU-seconds on this tiny fixture: τ = 0.1 sharpens the ranking
    # softmax (with τ = 1 the cosine logits span at most 2 and learning starts slowly), a larger lr.
    cfg = TrainConfig(
        epochs=20,
        learning_rate=2e-3,
        temperature=0.1,
        lr_schedule="cosine",
        augment=augment,
        weights=weights,
        threads=1,
    )
    result = train(synthetic, tmp_path / "run", model_cfg, cfg, progress=False)
    assert (tmp_path / "run" / METRICS_FILE).is_file() and (tmp_path / "run" / CURVES_FILE).is_file()
    assert 1 <= result.best_epoch <= 20

    index = load_index(synthetic)
    test_labels = load_images(index.split("test"), 64, index.default_epsilon_px()).labels
    chance = float(torch.bincount(test_labels).max()) / len(test_labels)  # always say the majority class
    ev = evaluate_checkpoint(tmp_path / "run", synthetic, "heldout")
    assert ev.n == 120
    assert ev.rank1 >= max(0.4, 1.6 * chance), (
        ev.rank1,
        chance,
    )  # chance 0.25 here; a broken model stays near it
    assert min(ev.x_accuracy, ev.z_accuracy) >= 0.7


def test_train_command_help_renders_and_cpu_is_the_default_preset() -> None:
    from dronectl.train_cmd import build_parser

    parser = build_parser()
    assert "label-exact" in parser.format_help()  # the preset notes hold '%', argparse must not choke
    assert parser.parse_args(["--data", "d", "--out", "o"]).preset == "cpu"


@pytest.mark.timeout(900)  # ~70 s on an idle core; several times that beside a loaded machine
def test_grounded_training_plans_toward_the_target_the_words_name(tmp_path: Path) -> None:
    """Two targets per image: asked for the named one, the model's moves follow the named one's offset,
    not the other's, so it must read the words (a model that ignores them scores ~half of this)."""
    from dataclasses import replace

    from controller.evaluation.evaluate import evaluate_loaded
    from controller.planning.latent.checkpoint import load_checkpoint

    one = write_synthetic_dataset(tmp_path / "one", n_goal=40, n_train=400, n_test=40, size=64, seed=1)
    data = write_synthetic_dataset(tmp_path / "two", n_goal=40, n_train=400, n_test=120, size=64, targets=2)
    model_cfg, cfg = small_grounded(epochs=30)
    # Single-target images teach where a target is; two-target images, which one the words mean.
    train([one, data], tmp_path / "run", model_cfg, cfg, progress=False)
    ckpt = load_checkpoint(tmp_path / "run")
    assert ckpt.model.presence is not None and ckpt.model.conditioned

    index = load_index(data)
    test = load_images(index.split("test"), 64, index.default_epsilon_px())
    named = evaluate_loaded(ckpt, test, "heldout")
    # The same images, with labels and instructions for the OTHER target: the words must move the choice.
    swapped = replace(
        test,
        targets=[(t[1], t[0]) for t in test.targets],
        labels=torch.tensor(
            [label_index(t[1].offset_px, index.default_epsilon_px()) for t in test.targets], dtype=torch.long
        ),
        kinds=[t[1].kind for t in test.targets],
    )
    other = evaluate_loaded(ckpt, swapped, "heldout")
    assert named.rank1 >= 0.7 and other.rank1 >= 0.7, (named.rank1, other.rank1)
    ev = evaluate_checkpoint(tmp_path / "run", data, "heldout")
    assert ev.presence is not None and ev.presence["auroc"] >= 0.8, ev.presence
    assert set(ev.by_targets_in_view) == {"2"}
    phrases = tmp_path / "operators.txt"
    phrases.write_text(
        "gauge: bring the pressure dial to the middle\nvalve: centre the valve wheel\n"
        "switchbox: line up on the control box\n"
    )
    by_phrase = evaluate_checkpoint(tmp_path / "run", data, str(phrases))
    assert by_phrase.n == 120 and by_phrase.rank1 >= 0.6, by_phrase.rank1


def label_index(offset: tuple[float, float], eps: float) -> int:
    from controller.planning.actions import label_from_offset

    return label_from_offset(offset[0], offset[1], eps).index


def _weights(run: Path) -> dict[str, torch.Tensor]:
    from safetensors.torch import load_file

    from controller.planning.latent.checkpoint import WEIGHTS_FILE

    return load_file(str(run / WEIGHTS_FILE))


def _one_epoch(synthetic: Path, out: Path, device: str = "cpu", **changes: object) -> dict[str, torch.Tensor]:
    model_cfg = ModelConfig(image_size=64, base_width=8, coord_channels=True, pooling="flatten")
    cfg = TrainConfig(epochs=1, learning_rate=1e-3, threads=1, **changes)  # type: ignore[arg-type]
    train(synthetic, out, model_cfg, cfg, progress=False, device=device)
    return _weights(out)


def test_channels_last_is_the_same_model_in_another_memory_order(synthetic: Path, tmp_path: Path) -> None:
    """A speed setting only: the same outputs and gradients up to summation order, and a checkpoint
    saved in the standard order that loads and passes its probe like any other."""
    import copy

    from controller.planning.latent.checkpoint import load_checkpoint
    from controller.planning.latent.model import LatentDynamicsModel
    from controller.training.train_described import model_input

    torch.manual_seed(0)
    cfg = ModelConfig(
        image_size=64, base_width=8, coord_channels=True, pooling="flatten", conditioning="film"
    )
    plain = LatentDynamicsModel(cfg)
    torch.nn.init.normal_(plain.image_encoder.film.weight, std=0.05)  # FiLM on (it starts as the identity)
    fast = copy.deepcopy(plain).to(memory_format=torch.channels_last)
    x = torch.rand(6, 3, 64, 64)
    ids = torch.randint(1, cfg.vocab_size, (6, 7))
    outs = []
    for model, channels_last in ((plain, False), (fast, True)):
        torch.manual_seed(1)  # the same dropout draws in the text encoder
        out = model.encode_images(model_input(model, x, channels_last), model.encode_text(ids))
        out.square().sum().backward()
        outs.append(out)
    torch.testing.assert_close(outs[1], outs[0], atol=1e-5, rtol=1e-4)
    for (name, a), (_, b) in zip(plain.named_parameters(), fast.named_parameters(), strict=True):
        if a.grad is not None:
            scale = float(a.grad.abs().max())  # first-layer gradients sum over every pixel: compare to scale
            assert float((b.grad - a.grad).abs().max()) <= 1e-4 * scale + 1e-7, name

    weights = _one_epoch(synthetic, tmp_path / "fast", channels_last=True)
    assert all(t.is_contiguous() for t in weights.values())
    load_checkpoint(tmp_path / "fast")  # the probe check inside recomputes the stored distances


def test_ema_saves_the_moving_average_of_the_weights(synthetic: Path, tmp_path: Path) -> None:
    """With a decay near 0 the average is the latest weights (the plain run's); with 0.9 it lags behind
    them; either way the saved checkpoint loads and passes its probe. The training draws are the same."""
    from controller.planning.latent.checkpoint import load_checkpoint

    plain = _one_epoch(synthetic, tmp_path / "plain")
    latest = _one_epoch(synthetic, tmp_path / "latest", ema_decay=1e-9)
    lagging = _one_epoch(synthetic, tmp_path / "lagging", ema_decay=0.9)
    for key, value in plain.items():
        torch.testing.assert_close(latest[key], value, atol=1e-6, rtol=1e-5, msg=key)
    moved = [k for k, v in plain.items() if v.is_floating_point() and not torch.allclose(lagging[k], v)]
    assert len(moved) > len(plain) // 2, moved
    load_checkpoint(tmp_path / "lagging")
    with pytest.raises(ValueError, match="ema_decay"):
        TrainConfig(ema_decay=1.0)


def test_an_unknown_or_missing_training_device_is_a_clear_error(synthetic: Path, tmp_path: Path) -> None:
    from controller.training.train import resolve_device

    assert resolve_device("cpu").type == "cpu"
    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(ValueError, match="unknown device"):
        resolve_device("gpu0")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="no CUDA GPU"):
            _one_epoch(synthetic, tmp_path / "run", device="cuda")
        assert not (tmp_path / "run").exists()  # refused before anything was written


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (training with --device cuda)")
def test_training_on_a_gpu_follows_the_cpu_run(synthetic: Path, tmp_path: Path) -> None:
    """Data and draws stay on the CPU, so a GPU run is the CPU run up to floating-point order."""
    cpu = _one_epoch(synthetic, tmp_path / "cpu")
    gpu = _one_epoch(synthetic, tmp_path / "gpu", device="cuda")
    for key in cpu:
        torch.testing.assert_close(gpu[key], cpu[key], atol=5e-3, rtol=2e-2, msg=key)


def test_mirror_tta_swaps_left_and_right_and_treats_an_image_and_its_mirror_alike(synthetic: Path) -> None:
    from dataclasses import replace

    from controller.evaluation.evaluate import evaluate_loaded
    from controller.planning.actions import ALL_ACTIONS, MIRRORED_INDEX
    from controller.planning.latent.checkpoint import load_checkpoint
    from controller.planning.planners import DEFAULT_CHECKPOINT

    MIRRORED_ACTION = torch.tensor(MIRRORED_INDEX)
    for action in ALL_ACTIONS:
        dx, dz = action.direction()
        assert ALL_ACTIONS[int(MIRRORED_ACTION[action.index])].direction() == (-dx, dz)
    ckpt = load_checkpoint(DEFAULT_CHECKPOINT)
    index = load_index(synthetic)
    data = load_images(index.split("test")[:24], ckpt.config.image_size, index.default_epsilon_px())
    mirrored = replace(
        data,
        images=data.images.flip(-1).contiguous(),
        labels=MIRRORED_ACTION[data.labels],
        offsets=data.offsets * torch.tensor([-1.0, 1.0]),
    )
    words = ["center the gauge"] * len(data)
    plain = evaluate_loaded(ckpt, data, instructions=words, mirror_tta=True)
    flipped = evaluate_loaded(ckpt, mirrored, instructions=words, mirror_tta=True)
    assert flipped.predictions == MIRRORED_ACTION[torch.tensor(plain.predictions)].tolist()
    assert flipped.rank1 == plain.rank1
    assert evaluate_loaded(ckpt, data, instructions=words).instructions == "train"  # off unless asked


def test_the_global_shifts_start_at_the_chosen_spread_from_the_same_draws() -> None:
    """`shift_init_std` scales g_X, g_Z's initial draws and nothing else: at the default the model is
    built exactly as it always was (checkpoints and seeds reproduce), at 0.5 the same draws × 50."""
    from controller.planning.latent.config import SHIFT_INIT_STD
    from controller.planning.latent.model import LatentDynamicsModel

    cfg = ModelConfig(image_size=32, base_width=4, latent_dim=16, text_heads=2)
    torch.manual_seed(3)
    plain = LatentDynamicsModel(cfg).state_dict()
    torch.manual_seed(3)
    wide = LatentDynamicsModel(cfg, shift_init_std=0.5).state_dict()
    for name, value in plain.items():
        expected = value * (0.5 / SHIFT_INIT_STD) if name in ("global_x", "global_z") else value
        torch.testing.assert_close(wide[name], expected, msg=name)
    assert float(wide["global_x"].std()) > 0.2 > 0.02 > float(plain["global_x"].std())
    assert TrainConfig().shift_init_std == SHIFT_INIT_STD
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="shift_init_std"):
            TrainConfig(shift_init_std=bad)


def test_train_uses_the_configured_shift_spread(synthetic: Path, tmp_path: Path) -> None:
    """The trainer builds its model with `TrainConfig.shift_init_std` (one epoch at lr 1e-9 leaves the
    shifts where they started)."""
    from safetensors.torch import load_file

    model_cfg = ModelConfig(image_size=64, base_width=4, latent_dim=16, text_heads=2)
    spreads = {}
    for std in (0.01, 1.0):
        out = tmp_path / f"s{std}"
        cfg = TrainConfig(epochs=1, learning_rate=1e-9, threads=1, shift_init_std=std)
        train(synthetic, out, model_cfg, cfg, progress=False)
        spreads[std] = float(load_file(out / "model.safetensors")["global_x"].std())
    assert spreads[0.01] < 0.05 and spreads[1.0] > 0.4, spreads
