"""PX4 saves its parameters after each arming change, and a parameter set during that save stalled a
lockstepped PX4 for good: `prepare_takeoff` sets the takeoff altitude only once the save is over.

MAVSDK's telemetry and action plugins are replaced by fakes (named so) that record what the backend
subscribes and sends; the flights themselves run against real PX4 in test_px4_sitl and test_warm_reset."""

from __future__ import annotations

import math
import time
from types import SimpleNamespace
from typing import Any

import pytest

from flight.mavsdk.link import PX4_PARAMETER_SAVE_GUARD_S, MavsdkConfig, TelemetryCache
from flight.mavsdk.vehicle import PARAMETER_SAVE_S, MavsdkVehicle


class FakeTelemetryPlugin:
    """Keeps each `subscribe_<stream>` callback, to be called as MAVSDK's thread would."""

    def __init__(self) -> None:
        self.callbacks: dict[str, Any] = {}

    def __getattr__(self, name: str) -> Any:
        if not name.startswith("subscribe_"):
            raise AttributeError(name)
        return lambda callback: self.callbacks.__setitem__(name.removeprefix("subscribe_"), callback)


class FakeSystem:
    def subscribe_is_connected(self, _callback: Any) -> None:
        pass


class FakeAction:
    """Records when each takeoff altitude was set."""

    def __init__(self) -> None:
        self.sets: list[tuple[float, float]] = []

    def set_takeoff_altitude(self, altitude_m: float) -> None:
        self.sets.append((time.monotonic(), altitude_m))


def _attitude(stamp_s: float) -> SimpleNamespace:
    return SimpleNamespace(roll_deg=0.0, pitch_deg=0.0, yaw_deg=0.0, timestamp_us=int(stamp_s * 1e6))


def test_the_cache_keeps_the_vehicle_time_of_the_last_arming_change_only() -> None:
    cache = TelemetryCache(2.0)
    plugin = FakeTelemetryPlugin()
    cache.subscribe(FakeSystem(), plugin)
    attitude, armed = plugin.callbacks["attitude_euler"], plugin.callbacks["armed"]
    attitude(_attitude(10.0), None)
    armed(False, None)  # the first report, not a change
    assert cache.armed_changed[0] == -math.inf
    armed(True, None)
    assert cache.armed_changed[0] == 10.0
    attitude(_attitude(12.5), None)
    armed(True, None)  # still armed: no change
    assert cache.armed_changed[0] == 10.0
    armed(False, None)
    assert cache.armed_changed[0] == 12.5 and not cache.armed


def _vehicle(guard_s: float) -> tuple[MavsdkVehicle, FakeAction]:
    vehicle = MavsdkVehicle(MavsdkConfig(url="udpin://127.0.0.1:14540", parameter_save_guard_s=guard_s))
    action = FakeAction()
    vehicle._action = action  # type: ignore[assignment]
    vehicle._cache.link.heard()
    return vehicle, action


def test_the_takeoff_altitude_waits_out_the_save_after_a_disarm() -> None:
    vehicle, action = _vehicle(guard_s=0.4)
    disarmed_at = time.monotonic()
    vehicle._cache.armed_changed = (math.nan, disarmed_at)  # just disarmed (wall clock)
    vehicle.prepare_takeoff(1.2)
    assert [alt for _, alt in action.sets] == [1.2]
    assert action.sets[0][0] - disarmed_at >= 0.4
    # The same altitude again is not set again, and so waits for nothing.
    vehicle._cache.armed_changed = (math.nan, time.monotonic())
    start = time.monotonic()
    vehicle.prepare_takeoff(1.2)
    assert len(action.sets) == 1 and time.monotonic() - start < 0.2


def test_an_arming_change_long_ago_costs_no_wait() -> None:
    vehicle, action = _vehicle(guard_s=0.4)
    vehicle._cache.armed_changed = (math.nan, time.monotonic() - 5.0)
    start = time.monotonic()
    vehicle.prepare_takeoff(1.2)
    assert action.sets[0][0] - start < 0.2  # set at once; then PX4's own save of it is waited out
    assert time.monotonic() - start >= PARAMETER_SAVE_S


def test_the_guard_is_px4s_by_default_and_never_negative() -> None:
    assert MavsdkConfig().parameter_save_guard_s == PX4_PARAMETER_SAVE_GUARD_S > 2.0  # PX4's 2 s rate limit
    with pytest.raises(ValueError, match="parameter_save_guard_s"):
        MavsdkConfig(parameter_save_guard_s=-1.0)
