"""A takeoff is not idempotent on PX4: every NAV_TAKEOFF it receives (MAVSDK sends the altitude as NaN)
starts a new takeoff to its current altitude plus MIS_TAKEOFF_ALT. Over a lossy link a copy that arrived
after liftoff once climbed PX4 to 6.04 m. So the backend sends a timed-out takeoff again only while the
vehicle shows no sign of it, and stops a takeoff that climbs `takeoff_overshoot_m` past its altitude.

MAVSDK's action plugin is replaced by a fake (named so) and telemetry is written into the backend's
cache as MAVSDK's thread would; real takeoffs run against PX4 in test_px4_sitl."""

from __future__ import annotations

import pytest
from mavsdk.plugins.action import ActionError, ActionResult

from flight.errors import FlightTimeoutError, TakeoffOvershootError
from flight.mavsdk.link import MavsdkConfig
from flight.mavsdk.vehicle import MavsdkVehicle
from flight.types import FlightMode


class FakeLossyAction:
    """Counts takeoffs; each times out (its acknowledgement lost) and `on_takeoff` says what the vehicle
    did with it. `hold` switches the cached mode to HOLD, as PX4's heartbeat would show."""

    def __init__(self, vehicle: MavsdkVehicle, on_takeoff: object) -> None:
        self.vehicle, self.on_takeoff = vehicle, on_takeoff
        self.takeoffs = 0
        self.holds = 0

    def takeoff(self) -> None:
        self.takeoffs += 1
        self.on_takeoff(self.vehicle._cache)  # type: ignore[operator]
        self.vehicle._cache.link.heard()
        raise ActionError(ActionResult.TIMEOUT, "takeoff()")

    def hold(self) -> None:
        self.holds += 1
        self.vehicle._cache.mode = FlightMode.HOLD
        self.vehicle._cache.link.heard()


def _armed_vehicle(on_takeoff: object) -> tuple[MavsdkVehicle, FakeLossyAction]:
    vehicle = MavsdkVehicle(MavsdkConfig(url="udpin://127.0.0.1:14540", link_timeout_s=5.0))
    action = FakeLossyAction(vehicle, on_takeoff)
    vehicle._action = action  # type: ignore[assignment]
    vehicle._takeoff_altitude_m = 1.0  # prepared: no parameter to set
    vehicle._ground_down_m = 0.0
    cache = vehicle._cache
    cache.armed, cache.in_air, cache.mode = True, False, FlightMode.HOLD
    cache.position = (0.0, 0.0, 0.0)
    cache.link.heard()
    return vehicle, action


def test_a_takeoff_the_vehicle_shows_is_not_sent_again_when_its_ack_is_lost() -> None:
    def started(cache: object) -> None:  # PX4 took it: TAKEOFF mode, climbing to 1 m
        cache.mode = FlightMode.TAKEOFF  # type: ignore[attr-defined]

    vehicle, action = _armed_vehicle(started)
    with pytest.raises(FlightTimeoutError):  # the fake never finishes the climb
        vehicle.takeoff(1.0, timeout_s=0.2)
    assert action.takeoffs == 1


def test_a_takeoff_the_vehicle_never_saw_is_sent_again() -> None:
    vehicle, action = _armed_vehicle(lambda cache: None)  # lost on the way: nothing changes
    with pytest.raises(Exception, match="TIMEOUT"):
        vehicle.takeoff(1.0, timeout_s=0.2)
    assert action.takeoffs == 3  # COMMAND_ATTEMPTS


def test_a_takeoff_that_climbs_past_its_limit_is_held_and_raised() -> None:
    def climbing_away(cache: object) -> None:  # copies of the command took it to 2.3 m, still climbing
        cache.mode, cache.in_air = FlightMode.TAKEOFF, True  # type: ignore[attr-defined]
        cache.position = (0.0, 0.0, -2.3)  # type: ignore[attr-defined]
        cache.velocity = (0.0, 0.0, -0.5)  # type: ignore[attr-defined]

    vehicle, action = _armed_vehicle(climbing_away)
    with pytest.raises(TakeoffOvershootError, match=r"2\.30 m on a takeoff to 1\.00 m"):
        vehicle.takeoff(1.0, timeout_s=5.0)
    assert action.takeoffs == 1 and action.holds == 1
    assert vehicle.telemetry().flight_mode == FlightMode.HOLD


def test_a_takeoff_within_the_limit_is_not_stopped() -> None:
    def arrived(cache: object) -> None:  # at 1.4 m, PX4's takeoff done: Hold, the climb over
        cache.mode, cache.in_air = FlightMode.HOLD, True  # type: ignore[attr-defined]
        cache.position = (0.0, 0.0, -1.4)  # type: ignore[attr-defined]
        cache.velocity = (0.0, 0.0, 0.0)  # type: ignore[attr-defined]

    vehicle, action = _armed_vehicle(arrived)
    vehicle.takeoff(1.0, timeout_s=2.0)
    assert action.takeoffs == 1 and action.holds == 0
