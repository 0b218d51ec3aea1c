"""The render mode: `auto` keeps the faster mode by an injected measurement; explicit modes skip it."""

from __future__ import annotations

import logging

import pytest

from sim_world.rendering.camera import CameraConfig
from sim_world.rendering.render_mode import CameraFeed, calibrate, choose_render_mode, hover_rtf
from sim_world.world import World, WorldConfig


def _never() -> dict[str, float]:
    raise AssertionError("an explicit mode must not calibrate")


@pytest.mark.parametrize(
    ("rtf", "expected"),
    [
        ({"single": 2.1, "workers": 3.4}, "workers"),
        ({"single": 2.1, "workers": 1.2}, "single"),
        ({"single": 2.1, "workers": 2.15}, "single"),  # within the 5 % margin: the simpler mode
    ],
)
def test_auto_keeps_the_faster_mode(rtf: dict[str, float], expected: str, caplog) -> None:
    with caplog.at_level(logging.INFO, logger="sim_world.rendering.render_mode"):
        choice = choose_render_mode("auto", lambda: rtf)
    assert choice.mode == expected and choice.requested == "auto"
    assert choice.calibration_rtf == rtf and "calibrated" in choice.reason
    assert f"render mode {expected}" in caplog.text


def test_explicit_modes_and_bad_input() -> None:
    for mode in ("single", "workers"):
        choice = choose_render_mode(mode, _never)
        assert (choice.mode, choice.reason, choice.calibration_rtf) == (mode, "explicit", None)
    with pytest.raises(ValueError, match="render mode"):
        choose_render_mode("gpu", _never)
    with pytest.raises(ValueError, match="no figure"):
        choose_render_mode("auto", lambda: {"single": 1.0})


@pytest.mark.timeout(120)
def test_camera_feed_renders_every_camera_tick_in_both_modes() -> None:
    config = WorldConfig(camera=CameraConfig(width=64, height=64))
    with World(config, 3) as world:
        for mode in ("single", "workers"):
            with CameraFeed(mode, config, 3, workers=2) as feed:
                rtf = hover_rtf(world, feed, sim_s=0.5, camera_hz=30.0)
                assert feed.frames == 15 and rtf > 0.0  # 120 steps at 240 Hz, a frame every 8
    with pytest.raises(ValueError, match="render mode"):
        CameraFeed("auto", config, 3)


@pytest.mark.timeout(180)
def test_calibrate_measures_both_modes() -> None:
    config = WorldConfig(camera=CameraConfig(width=64, height=64))
    rtf = calibrate(config, 3, sim_s=0.25, rounds=2)
    assert set(rtf) == {"single", "workers"} and all(v > 0.0 for v in rtf.values())
