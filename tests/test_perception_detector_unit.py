"""Detector network, targets, decoding and checkpoints (no dataset needed)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from perception.training.data import make_targets
from perception.detector_model import EDGE_SCALE_PX, CentreNet, DetectorConfig, fuse_for_inference
from perception.errors import DetectorCheckpointError
from perception.image_detector import ImageDetector, load_model, normalise, save_checkpoint

SMALL = DetectorConfig(input_size=64, widths=(4, 8, 8, 8, 8), neck_width=8)


def test_output_shape_and_fusion_keeps_outputs() -> None:
    torch.manual_seed(0)
    model = CentreNet(SMALL)
    for module in model.modules():  # non-trivial batch-norm statistics
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.uniform_(-0.5, 0.5)
            module.running_var.uniform_(0.5, 2.0)
    model.eval()
    x = normalise(torch.randint(0, 256, (2, 3, 64, 64), dtype=torch.uint8))
    with torch.no_grad():
        before = model(x)
        after = fuse_for_inference(model)(x)
    assert before.shape == (2, 3 + 6, 16, 16)
    assert torch.allclose(before, after, atol=1e-4)


def test_targets_peak_offset_and_edges() -> None:
    centres = torch.tensor([[33.0, 18.0], [10.0, 10.0]])
    bboxes = torch.tensor([[25.0, 12.0, 41.0, 30.0], [0.0, 0.0, 0.0, 0.0]])
    kinds = torch.tensor([2, -1])
    t = make_targets(centres, bboxes, kinds, num_kinds=3, grid=16)
    assert t.heatmap.shape == (2, 3, 16, 16)
    assert t.heatmap[0, 2, 4, 8] == 1.0  # cell (u // 4, v // 4) = (8, 4), kind channel 2
    assert t.heatmap[0, :2].max() == 0.0 and t.heatmap[1].max() == 0.0  # other kinds, negatives
    assert int(t.reg_mask[0].sum()) == 9 and int(t.reg_mask[1].sum()) == 0
    assert t.offset[0, :, 4, 8].tolist() == pytest.approx([0.25, 0.5])  # 33/4 - 8, 18/4 - 4
    assert t.offset[0, :, 5, 9].tolist() == pytest.approx([-0.75, -0.5])
    assert t.edges[0, :, 4, 8].tolist() == pytest.approx([math.log(d / EDGE_SCALE_PX) for d in (8, 6, 8, 12)])


def test_decode_conventions() -> None:
    detector = ImageDetector(CentreNet(DetectorConfig()))
    out = torch.full((9, 56, 56), -10.0)
    out[1, 10, 20] = 3.0  # kind 1 (valve) at cell i=20, j=10
    out[3:5, 10, 20] = torch.tensor([0.25, 0.75])
    out[5:9, 10, 20] = math.log(8.0 / EDGE_SCALE_PX)
    det = detector._decode(out, 224, 224)
    assert det is not None and det.kind == "valve"
    assert det.centre_px == pytest.approx((81.0, 43.0))
    assert det.bbox_px == pytest.approx((73.0, 35.0, 89.0, 51.0))
    assert det.confidence == pytest.approx(1 / (1 + math.exp(-3.0)))
    scaled = detector._decode(out, 448, 448)  # a bigger frame: pixels scale back
    assert scaled is not None and scaled.centre_px == pytest.approx((162.0, 86.0))
    out[1, 10, 20] = -1.0  # below the 0.5 threshold
    assert detector._decode(out, 224, 224) is None


def test_checkpoint_round_trip(tmp_path: Path) -> None:
    torch.manual_seed(1)
    model = CentreNet(SMALL).eval()
    save_checkpoint(tmp_path, model, {"training": {"epochs": 1}})
    loaded = load_model(tmp_path)
    x = normalise(torch.randint(0, 256, (1, 3, 64, 64), dtype=torch.uint8))
    with torch.no_grad():
        assert torch.equal(model(x), loaded(x))
    assert loaded.config == SMALL
    image = np.zeros((64, 64, 3), np.uint8)
    det = ImageDetector(loaded, score_threshold=0.01).detect(image)
    assert det is not None and 0 <= det.centre_px[0] <= 64  # untrained: some peak, inside the frame


def test_corrupt_checkpoints_name_the_file(tmp_path: Path) -> None:
    save_checkpoint(tmp_path, CentreNet(SMALL))
    weights, config = tmp_path / "model.safetensors", tmp_path / "config.json"
    good = weights.read_bytes()
    weights.write_bytes(b"\x00garbage" * 10)
    with pytest.raises(DetectorCheckpointError, match=r"model\.safetensors: corrupt"):
        load_model(tmp_path)
    weights.write_bytes(good[: len(good) // 2])
    with pytest.raises(DetectorCheckpointError, match=r"model\.safetensors"):
        load_model(tmp_path)
    weights.write_bytes(good)
    payload = json.loads(config.read_text())
    payload["detector"]["neck_width"] = 16  # no longer matches the weights
    config.write_text(json.dumps(payload))
    with pytest.raises(DetectorCheckpointError, match=r"does not match config\.json"):
        load_model(tmp_path)
    payload["detector"]["bogus"] = 1
    config.write_text(json.dumps(payload))
    with pytest.raises(DetectorCheckpointError, match=r"config\.json: field 'detector': unknown field"):
        load_model(tmp_path)
    config.write_text("{not json")
    with pytest.raises(DetectorCheckpointError, match=r"config\.json: unreadable"):
        load_model(tmp_path)
    config.unlink()
    with pytest.raises(DetectorCheckpointError, match=r"config\.json: missing"):
        load_model(tmp_path)
