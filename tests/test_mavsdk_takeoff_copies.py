"""A takeoff is not idempotent on PX4: every NAV_TAKEOFF it receives (MAVSDK sends the altitude as NaN)
starts a new takeoff to its current altitude plus MIS_TAKEOFF_ALT. Over a lossy link a copy that arrived
after liftoff once climbed PX4 to 6.04 m. So the backend sends a timed-out takeoff again only while the
vehicle shows no sign of it, and stops a takeoff that climbs `takeoff_overshoot_m` past its altitude.
And PX4 disarms on its own 10 s (of its clock) after arming without a takeoff, then accepts a takeoff it
never flies: the backend arms again and asks again, once, instead of waiting out its takeoff timeout.

MAVSDK's action plugin is replaced by a fake (named so) and telemetry is written into the backend's
cache as MAVSDK's thread would; real takeoffs run against PX4 in test_px4_sitl."""

from __future__ import annotations

import pytest
from mavsdk.plugins.action import ActionError, ActionResult

from flight.errors import CommandDeniedError, FlightTimeoutError, TakeoffOvershootError
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
        self.arms = 0

    def takeoff(self) -> None:
        self.takeoffs += 1
        self.on_takeoff(self.vehicle._cache, self.takeoffs)  # type: ignore[operator]
        self.vehicle._cache.link.heard()
        raise ActionError(ActionResult.TIMEOUT, "takeoff()")

    def arm(self) -> None:
        self.arms += 1
        self.vehicle._cache.armed = True
        self.vehicle._cache.link.heard()

    def hold(self) -> None:
        self.holds += 1
        self.vehicle._cache.mode = FlightMode.HOLD
        self.vehicle._cache.link.heard()


def _armed_vehicle(on_takeoff: object, armed_here: bool = True) -> tuple[MavsdkVehicle, FakeLossyAction]:
    vehicle = MavsdkVehicle(MavsdkConfig(url="udpin://127.0.0.1:14540", link_timeout_s=5.0))
    action = FakeLossyAction(vehicle, on_takeoff)
    vehicle._action = action  # type: ignore[assignment]
    vehicle._takeoff_altitude_m = 1.0  # prepared: no parameter to set
    vehicle._ground_down_m = 0.0
    cache = vehicle._cache
    cache.armed, cache.in_air, cache.mode = True, False, FlightMode.HOLD
    cache.position = (0.0, 0.0, 0.0)
    cache.link.heard()
    vehicle._arm_asked = armed_here  # as after this backend's arm()
    return vehicle, action


def test_a_takeoff_the_vehicle_shows_is_not_sent_again_when_its_ack_is_lost() -> None:
    def started(cache: object, _n: int) -> None:  # PX4 took it: TAKEOFF mode, climbing to 1 m
        cache.mode = FlightMode.TAKEOFF  # type: ignore[attr-defined]

    vehicle, action = _armed_vehicle(started)
    with pytest.raises(FlightTimeoutError):  # the fake never finishes the climb
        vehicle.takeoff(1.0, timeout_s=0.2)
    assert action.takeoffs == 1


def test_a_takeoff_the_vehicle_never_saw_is_sent_again() -> None:
    vehicle, action = _armed_vehicle(lambda cache, _n: None)  # lost on the way: nothing changes
    with pytest.raises(Exception, match="TIMEOUT"):
        vehicle.takeoff(1.0, timeout_s=0.2)
    assert action.takeoffs == 3  # COMMAND_ATTEMPTS


def test_a_takeoff_that_climbs_past_its_limit_is_held_and_raised() -> None:
    def climbing_away(cache: object, _n: int) -> None:  # copies of the command took it to 2.3 m, climbing
        cache.mode, cache.in_air = FlightMode.TAKEOFF, True  # type: ignore[attr-defined]
        cache.position = (0.0, 0.0, -2.3)  # type: ignore[attr-defined]
        cache.velocity = (0.0, 0.0, -0.5)  # type: ignore[attr-defined]

    vehicle, action = _armed_vehicle(climbing_away)
    with pytest.raises(TakeoffOvershootError, match=r"2\.30 m on a takeoff to 1\.00 m"):
        vehicle.takeoff(1.0, timeout_s=5.0)
    assert action.takeoffs == 1 and action.holds == 1
    assert vehicle.telemetry().flight_mode == FlightMode.HOLD


def test_a_takeoff_within_the_limit_is_not_stopped() -> None:
    def arrived(cache: object, _n: int) -> None:  # at 1.4 m, PX4's takeoff done: Hold, the climb over
        cache.mode, cache.in_air = FlightMode.HOLD, True  # type: ignore[attr-defined]
        cache.position = (0.0, 0.0, -1.4)  # type: ignore[attr-defined]
        cache.velocity = (0.0, 0.0, 0.0)  # type: ignore[attr-defined]

    vehicle, action = _armed_vehicle(arrived)
    vehicle.takeoff(1.0, timeout_s=2.0)
    assert action.takeoffs == 1 and action.holds == 0


def _arrive(cache: object) -> None:
    cache.mode, cache.in_air = FlightMode.HOLD, True  # type: ignore[attr-defined]
    cache.position, cache.velocity = (0.0, 0.0, -1.0), (0.0, 0.0, 0.0)  # type: ignore[attr-defined]


def test_a_vehicle_that_disarmed_on_the_ground_is_armed_and_asked_again_once() -> None:
    def disarmed_first(cache: object, n: int) -> None:  # PX4 had disarmed: it takes the command, never flies
        if n == 1:
            cache.mode, cache.armed = FlightMode.TAKEOFF, False  # type: ignore[attr-defined]
        else:
            _arrive(cache)

    vehicle, action = _armed_vehicle(disarmed_first)
    vehicle.takeoff(1.0, timeout_s=5.0)
    assert (action.takeoffs, action.arms) == (2, 1)


def test_a_vehicle_that_keeps_disarming_is_a_refusal_not_a_30_s_wait() -> None:
    def always_disarmed(cache: object, _n: int) -> None:
        cache.mode, cache.armed = FlightMode.TAKEOFF, False  # type: ignore[attr-defined]

    vehicle, action = _armed_vehicle(always_disarmed)
    with pytest.raises(CommandDeniedError, match="DISARMED"):
        vehicle.takeoff(1.0, timeout_s=30.0)
    assert (action.takeoffs, action.arms) == (2, 1)


def test_a_vehicle_this_backend_never_armed_is_not_armed_by_a_takeoff() -> None:
    def accepted_disarmed(cache: object, _n: int) -> None:  # as PX4 does: TAKEOFF mode, on the ground
        cache.mode = FlightMode.TAKEOFF  # type: ignore[attr-defined]

    vehicle, action = _armed_vehicle(accepted_disarmed, armed_here=False)
    vehicle._cache.armed = False
    with pytest.raises(CommandDeniedError, match="NOT_ARMED"):
        vehicle.takeoff(1.0, timeout_s=30.0)
    assert (action.takeoffs, action.arms) == (1, 0)
