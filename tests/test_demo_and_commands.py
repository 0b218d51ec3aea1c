"""The demo flight and the command-line adapters of collect / bench / demo."""

from __future__ import annotations

from pathlib import Path

import cv2
import pytest
from dronectl import bench_cmd, collect_cmd, demo_cmd

from sim_world.collection.demo import DemoConfig, run_demo
from sim_world.rendering.camera import CameraConfig
from sim_world.world import WorldConfig


def test_demo_flies_right_then_left_and_the_target_moves_the_other_way(tmp_path: Path) -> None:
    config = DemoConfig(
        out_dir=tmp_path,
        seconds=8.5,
        frames_per_s=2.0,
        seed=2,
        world=WorldConfig(camera=CameraConfig(width=96, height=96)),
    )
    result = run_demo(config)
    assert result.landed
    assert len(result.frames) == 17  # 8.5 s at 2 frames/s
    image = cv2.imread(str(result.frames[0].image))
    assert image is not None and image.shape == (96, 96, 3)
    by_leg = {}
    for frame in result.frames:
        assert frame.offset_px is not None
        by_leg.setdefault(frame.leg, []).append(frame.offset_px[0])
    # Flying right moves the target left in the image, flying left moves it back right.
    assert by_leg["right"][-1] < by_leg["right"][0] - 5.0
    assert by_leg["left"][-1] > by_leg["left"][0] + 5.0


def test_commands_refuse_bad_input_with_a_clear_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("target:\n  size_m: [0.5, 0.2]\n")
    assert collect_cmd.main(["--out", str(tmp_path / "d"), "--seed", "0", "--scene", str(bad)]) == 2
    assert "target.size_m" in capsys.readouterr().err
    assert collect_cmd.main(["--out", str(tmp_path / "d"), "--seed", "0", "--n-goal", "-1"]) == 2
    assert "n_goal" in capsys.readouterr().err
    assert demo_cmd.main(["--out", str(tmp_path / "demo"), "--seconds", "0"]) == 2
    assert "seconds" in capsys.readouterr().err
    assert bench_cmd.main(["warp"]) == 2
    assert "unknown benchmark 'warp'" in capsys.readouterr().err


def test_bench_dispatches_to_the_module_bench_main(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        bench_cmd.main(["sim", "--help"])
    assert stop.value.code == 0
    assert "dronectl bench sim" in capsys.readouterr().out
