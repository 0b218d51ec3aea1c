"""The ONNX Runtime backends give the torch backends' outputs on the same inputs.

Planner: the distances (and presence) within 1e-4 and the same chosen action, on the shipped
checkpoint and on a FiLM-conditioned checkpoint with a presence head (the `grounded` preset's
architecture), for random and rendered images. Detector: the raw head outputs within 1e-4 and
the same detections. Also the backend choice: "auto" takes ONNX when onnxruntime is installed,
"onnx" without it is a typed error, an unknown name a ValueError.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from latent_synthetic import write_synthetic_dataset

import drone_inspect_core.onnx_runtime as onnx_runtime
import tools.bench_inference as bench_inference
from controller.planning.latent.checkpoint import save_checkpoint
from controller.planning.latent.config import PRESETS
from controller.training.instructions import tokenizer_corpus
from controller.planning.latent.model import LatentDynamicsModel
from controller.planning.latent.planner import LatentPlanner
from controller.planning.latent.tokenizer import InstructionTokenizer
from controller.planning.planners import DEFAULT_CHECKPOINT
from drone_inspect_core.onnx_runtime import OnnxBackendError
from perception.image_detector import ImageDetector

pytest.importorskip("onnxruntime")

INSTRUCTIONS = ("center the gauge", "please centre the red valve")


@pytest.fixture(scope="module")
def frames() -> list[np.ndarray]:
    """Four 224 px renders (target in view at several offsets, one looking away) and four noise images."""
    from sim_world.world import World

    rendered = []
    with World(seed=4321) as world:
        for right_m, up_m, yaw_deg in ((0.0, 0.0, 0.0), (0.4, -0.2, 5.0), (-0.5, 0.3, -8.0), (3.0, 0.0, 0.0)):
            world.teleport(*world.scene.pose_for_offset(right_m, up_m, 2.0, yaw_deg))
            rendered.append(world.render(with_seg=False).rgb)
    rng = np.random.default_rng(5)
    return rendered + [rng.integers(0, 256, (224, 224, 3), dtype=np.uint8) for _ in range(4)]


@pytest.fixture(scope="module")
def film_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Random weights in the grounded preset's architecture: FiLM-conditioned E_img and a presence head."""
    torch.manual_seed(11)
    tokenizer = InstructionTokenizer.train(tokenizer_corpus())
    config = replace(PRESETS["grounded"].model, image_size=64, base_width=8, vocab_size=tokenizer.vocab_size)
    model = LatentDynamicsModel(config)
    assert model.image_encoder.film is not None and model.presence is not None
    torch.nn.init.normal_(model.image_encoder.film.weight, std=0.05)  # FiLM starts as the identity
    for module in model.modules():  # trained-looking batch-norm statistics, so folding them matters
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.uniform_(-0.5, 0.5)
            module.running_var.uniform_(0.5, 2.0)
    folder = tmp_path_factory.mktemp("film")
    save_checkpoint(folder, model, tokenizer, torch.randn(config.latent_dim))
    return folder


def _assert_planners_agree(folder: Path, frames: list[np.ndarray]) -> None:
    on_torch = LatentPlanner(folder, backend="torch")
    on_onnx = LatentPlanner(folder, backend="onnx")
    assert (on_torch.backend, on_onnx.backend) == ("torch", "onnx")
    for instruction in INSTRUCTIONS:
        want_actions, want, want_presence = on_torch.plan_with_presence(frames, instruction)
        got_actions, got, got_presence = on_onnx.plan_with_presence(frames, instruction)  # a batch
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-4)
        assert got_actions == want_actions
        assert (got_presence is None) == (want_presence is None) == (not on_torch.has_presence)
        if want_presence is not None:
            np.testing.assert_allclose(got_presence, want_presence, rtol=0, atol=1e-4)
        for frame, row in zip(frames, want, strict=True):  # one decision at a time, as in flight
            action, distances = on_onnx.plan(frame, instruction)
            np.testing.assert_allclose(distances, row, rtol=0, atol=1e-4)
            assert action.index == int(np.argmin(row))


def test_shipped_planner_onnx_equals_torch(frames: list[np.ndarray]) -> None:
    _assert_planners_agree(DEFAULT_CHECKPOINT, frames)


def test_film_planner_with_presence_onnx_equals_torch(
    film_checkpoint: Path, frames: list[np.ndarray]
) -> None:
    _assert_planners_agree(film_checkpoint, frames)


def test_shipped_detector_onnx_equals_torch(frames: list[np.ndarray]) -> None:
    on_torch = ImageDetector.shipped(backend="torch")
    on_onnx = ImageDetector.shipped(backend="onnx")
    assert (on_torch.backend, on_onnx.backend) == ("torch", "onnx")
    with torch.inference_mode():
        want, got = on_torch._forward(frames), on_onnx._forward(frames)
    assert got.shape == want.shape == (len(frames), on_torch.config.num_outputs, 56, 56)
    np.testing.assert_allclose(got.numpy(), want.numpy(), rtol=0, atol=1e-4)
    found = [d for d in on_torch.detect_batch(frames) if d is not None]
    assert len(found) >= 3  # the three renders with the target in view
    for frame in frames:
        want_all, got_all = on_torch.detect_all(frame), on_onnx.detect_all(frame)
        assert [(d.kind, d.attribute) for d in got_all] == [(d.kind, d.attribute) for d in want_all]
        for a, b in zip(got_all, want_all, strict=True):
            np.testing.assert_allclose(a.bbox_px + a.centre_px, b.bbox_px + b.centre_px, atol=1e-2)
            assert a.confidence == pytest.approx(b.confidence, abs=1e-4)


def test_auto_takes_onnx_when_installed_and_torch_when_not(monkeypatch: pytest.MonkeyPatch) -> None:
    assert LatentPlanner(DEFAULT_CHECKPOINT).backend == "onnx"
    monkeypatch.setattr(onnx_runtime, "onnxruntime_available", lambda: False)
    assert LatentPlanner(DEFAULT_CHECKPOINT).backend == "torch"
    assert ImageDetector.shipped().backend == "torch"
    with pytest.raises(OnnxBackendError, match="onnxruntime"):
        LatentPlanner(DEFAULT_CHECKPOINT, backend="onnx")
    with pytest.raises(ValueError, match="backend must be one of"):
        ImageDetector.shipped(backend="tensorrt")


def test_a_graph_that_disagrees_is_refused_and_auto_falls_back(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(onnx_runtime, "EXPORT_TOLERANCE", -1.0)  # every export now "disagrees"
    with pytest.raises(OnnxBackendError, match="differs from torch"):
        ImageDetector.shipped(backend="onnx")
    assert ImageDetector.shipped(backend="auto").backend == "torch"


def test_time_side_by_side_times_every_backend_in_alternating_rounds() -> None:
    order: list[str] = []
    calls = {name: (lambda i, name=name: order.append(name)) for name in ("torch", "onnx")}
    stats = onnx_runtime.time_side_by_side(calls, repeats=8, rounds=4, warmup=1)
    assert {name: s["calls"] for name, s in stats.items()} == {"torch": 8, "onnx": 8}
    assert order[2:] == (["torch"] * 2 + ["onnx"] * 2) * 4  # after one warm-up call each
    assert all(0.0 <= s["p50_ms"] <= s["p99_ms"] <= s["max_ms"] for s in stats.values())


def test_bench_inference_reports_both_backends(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = write_synthetic_dataset(tmp_path / "data", n_goal=2, n_train=2, n_test=6, size=96)
    argv = ["--data", str(data), "--decisions", "8", "--frames", "8", "--json", str(tmp_path / "b.json")]
    assert bench_inference.main(argv) == 0
    result = json.loads((tmp_path / "b.json").read_text())
    assert result["planner"]["max_abs_distance_difference"] <= 1e-4 and result["planner"]["same_actions"]
    assert result["detector"]["max_abs_head_difference"] <= 1e-4 and result["detector"]["same_kinds"]
    for model in ("planner", "detector"):
        assert {b: t["calls"] for b, t in result[model]["latency"].items()} == {"torch": 8, "onnx": 8}
    assert "planner: 6 frames" in capsys.readouterr().out
