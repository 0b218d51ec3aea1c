"""The discrete-move helper: displacement from telemetry, settling, setpoint refresh (FakeVehicle)."""

from __future__ import annotations

import pytest
from fake_vehicle import FakeVehicle

from flight.moves import execute_move
from flight.safe_vehicle import SafeVehicle
from flight.safety import SafetyLimits
from flight.types import VelocityBody


def offboard_fake(yaw_deg: float = 0.0, lag_s: float = 0.2) -> FakeVehicle:
    fake = FakeVehicle(yaw_deg=yaw_deg, lag_s=lag_s)
    fake.arm()
    fake.takeoff(2.0)
    fake.set_velocity_body(VelocityBody())
    fake.start_offboard()
    return fake


def test_move_right_reports_the_displacement_measured_by_telemetry() -> None:
    fake = offboard_fake()
    result = execute_move(fake, VelocityBody(right_m_s=0.25), duration_s=2.0)
    assert result.settled
    assert result.displacement.right_m == pytest.approx(0.5, abs=0.02)
    assert result.displacement.east_m == pytest.approx(0.5, abs=0.02)
    assert result.displacement.forward_m == pytest.approx(0.0, abs=1e-6)
    assert fake.commands[-1].is_zero()  # it ends holding
    assert 0.0 < result.settle_time_s < 5.0


def test_body_displacement_follows_the_start_heading() -> None:
    fake = offboard_fake(yaw_deg=90.0)  # facing east: right is south
    result = execute_move(fake, VelocityBody(right_m_s=0.25), duration_s=2.0)
    assert result.displacement.north_m == pytest.approx(-0.5, abs=0.02)
    assert result.displacement.right_m == pytest.approx(0.5, abs=0.02)


def test_setpoint_is_refreshed_at_the_command_period_not_in_a_tight_loop() -> None:
    fake = offboard_fake()
    before = len(fake.commands)
    execute_move(fake, VelocityBody(forward_m_s=0.2), duration_s=1.0, command_period_s=0.1)
    moving = [c for c in fake.commands[before:] if not c.is_zero()]
    assert 9 <= len(moving) <= 11


def test_a_slow_vehicle_is_reported_unsettled() -> None:
    fake = offboard_fake(lag_s=3.0)
    result = execute_move(fake, VelocityBody(right_m_s=0.5), duration_s=1.0, settle_timeout_s=0.3)
    assert not result.settled
    assert result.settle_time_s == pytest.approx(0.3, abs=0.11)


def test_move_through_the_safety_layer_is_clipped() -> None:
    fake = offboard_fake()
    vehicle = SafeVehicle(fake, SafetyLimits(max_horizontal_speed_m_s=0.2, geofence=None))
    result = execute_move(vehicle, VelocityBody(right_m_s=1.0), duration_s=2.0)
    assert result.displacement.right_m == pytest.approx(0.4, abs=0.02)


@pytest.mark.parametrize(
    "kwargs", [{"duration_s": -1.0}, {"duration_s": float("nan")}, {"settle_timeout_s": 0.0}]
)
def test_bad_arguments_are_rejected(kwargs: dict[str, float]) -> None:
    args = {"duration_s": 1.0} | kwargs
    with pytest.raises(ValueError):
        execute_move(offboard_fake(), VelocityBody(right_m_s=0.1), **args)
