"""On the vehicle's clock, a wait in offboard streams the last setpoint every `offboard_stream_period_s`
of that clock, counted from the last setpoint that went out, however the caller cuts its waits.

A lockstepped simulator (sim-vehicle at "max") runs only `lockstep_lead_s` past each setpoint and then
stands until the next one. When each wait's stream was counted from the wait's own start, a settle
polled in 0.1 s waits ended every wait exactly as the vehicle reached its lead, the next wait found the
clock standing short of its first setpoint, and the vehicle stood until its silence fallback (0.25 s of
wall time a wait): the settle ran at ×2 where the move before it ran at ×12.

MAVSDK's offboard plugin is replaced by a fake (named so) that plays that lockstep on the telemetry
cache's clock; the real pairing runs in test_flight_mavsdk and the sim-mavlink missions."""

from __future__ import annotations

import pytest

from flight.errors import LinkLostError
from flight.mavsdk.link import MavsdkConfig
from flight.mavsdk.vehicle import MavsdkVehicle
from flight.types import FlightMode, VelocityBody

LEAD_S = 0.1  # sim-vehicle's `lockstep_lead_s`


class FakeLockstepOffboard:
    """Each setpoint lets the vehicle's clock run `LEAD_S` past the time it arrived; then the clock
    stands, still reporting (telemetry flows while a lockstep holds), until the next setpoint."""

    def __init__(self, vehicle: MavsdkVehicle) -> None:
        self.cache = vehicle._cache
        self.sent_at: list[float] = []

    def set_velocity_body(self, _setpoint: object) -> None:
        now = self.cache.vehicle_time_s
        self.sent_at.append(now)
        self.cache.vehicle_time_s = round(now + LEAD_S, 9)
        self.cache.link.heard()


def _offboard_vehicle() -> tuple[MavsdkVehicle, FakeLockstepOffboard]:
    config = MavsdkConfig(url="udpin://127.0.0.1:14540", clock="vehicle", link_timeout_s=1.0)
    vehicle = MavsdkVehicle(config)
    offboard = FakeLockstepOffboard(vehicle)
    vehicle._offboard = offboard  # type: ignore[assignment]
    vehicle._cache.vehicle_time_s = 100.0
    vehicle._cache.mode = FlightMode.OFFBOARD
    vehicle._cache.link.heard()
    vehicle._in_offboard = True
    return vehicle, offboard


@pytest.mark.parametrize("wait_s", [0.03, 0.05, 0.1, 0.25])
def test_waits_of_any_length_keep_a_lockstep_going(wait_s: float) -> None:
    vehicle, offboard = _offboard_vehicle()
    vehicle.set_velocity_body(VelocityBody())  # as execute_move's hold: the clock runs to 100.1
    for _ in range(6):  # as execute_move's settle: a wait, then a look at the speed
        vehicle.sleep(wait_s)
    assert vehicle.time_s() >= 100.0 + 6 * wait_s
    gaps = [b - a for a, b in zip(offboard.sent_at, offboard.sent_at[1:], strict=False)]
    assert len(gaps) >= 5 and max(gaps) == pytest.approx(LEAD_S)  # never a stall past the lead


def test_no_setpoint_is_streamed_outside_offboard() -> None:
    vehicle, offboard = _offboard_vehicle()
    vehicle._in_offboard = False
    vehicle._cache.link.heard()
    with pytest.raises(LinkLostError):
        vehicle.sleep(0.1)  # nothing moves the clock, and nothing is streamed to move it
    assert offboard.sent_at == []
