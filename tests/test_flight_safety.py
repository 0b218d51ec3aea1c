"""Safety layer: speed clipping, geofence, setpoint watchdog, safe stop (unit tests over FakeVehicle)."""

from __future__ import annotations

import math
import time

import pytest
from fake_vehicle import FakeVehicle

from flight.errors import FlightError, GeofenceBreachError, LinkLostError
from flight.safe_vehicle import SafeVehicle
from flight.safety import GeofenceBox, SafetyLimits, clip_speed, flight_guard, safe_stop
from flight.types import FlightMode, Telemetry, VelocityBody

LIMITS = SafetyLimits(max_horizontal_speed_m_s=1.0, max_vertical_speed_m_s=0.5, max_yaw_rate_deg_s=30.0)


def flying(fake: FakeVehicle, limits: SafetyLimits = LIMITS) -> SafeVehicle:
    vehicle = SafeVehicle(fake, limits)
    vehicle.arm()
    vehicle.takeoff(2.0)
    vehicle.set_velocity_body(VelocityBody())
    vehicle.start_offboard()
    return vehicle


def test_clip_speed_scales_horizontal_keeping_direction_and_clips_vertical_and_yaw() -> None:
    clipped = clip_speed(VelocityBody(3.0, 4.0, -2.0, 90.0), LIMITS)
    assert clipped.forward_m_s == pytest.approx(0.6)
    assert clipped.right_m_s == pytest.approx(0.8)
    assert clipped.down_m_s == pytest.approx(-0.5)
    assert clipped.yawspeed_deg_s == pytest.approx(30.0)
    within = VelocityBody(0.3, -0.2, 0.1, -5.0)
    assert clip_speed(within, LIMITS) == within


def test_commands_above_the_limit_never_reach_the_backend() -> None:
    fake = FakeVehicle()
    vehicle = flying(fake)
    vehicle.set_velocity_body(VelocityBody(0.0, 5.0, 3.0, -200.0))
    sent = fake.commands[-1]
    assert sent.right_m_s == pytest.approx(1.0)
    assert sent.down_m_s == pytest.approx(0.5)
    assert sent.yawspeed_deg_s == pytest.approx(-30.0)
    assert max(c.horizontal_m_s for c in fake.commands) <= 1.0 + 1e-9


def test_non_finite_velocity_is_rejected() -> None:
    with pytest.raises(ValueError, match="right_m_s"):
        VelocityBody(0.0, math.nan)


@pytest.mark.parametrize("yaw_deg", [0.0, 90.0])
def test_geofence_drops_the_outward_component_near_the_edge(yaw_deg: float) -> None:
    fence = GeofenceBox(half_width_north_m=5.0, half_width_east_m=2.0, max_up_m=4.0, lookahead_s=0.5)
    fake = FakeVehicle(yaw_deg=yaw_deg)
    vehicle = flying(fake, SafetyLimits(geofence=fence))
    fake.position[1] = 1.8  # 0.2 m inside the east edge
    toward_east = VelocityBody(0.8, 0.0) if yaw_deg == 90.0 else VelocityBody(0.0, 0.8)
    vehicle.set_velocity_body(toward_east)
    assert fake.commands[-1].horizontal_m_s == pytest.approx(0.0, abs=1e-9)
    away = VelocityBody(-0.8, 0.0) if yaw_deg == 90.0 else VelocityBody(0.0, -0.8)
    vehicle.set_velocity_body(away)
    assert fake.commands[-1].horizontal_m_s == pytest.approx(0.8)


def test_geofence_keeps_the_inward_axis_of_a_diagonal_command() -> None:
    fence = GeofenceBox(half_width_north_m=5.0, half_width_east_m=2.0)
    fake = FakeVehicle()
    vehicle = flying(fake, SafetyLimits(geofence=fence))
    fake.position[1] = 1.9
    vehicle.set_velocity_body(VelocityBody(forward_m_s=0.5, right_m_s=0.5))
    assert fake.commands[-1].forward_m_s == pytest.approx(0.5)
    assert fake.commands[-1].right_m_s == pytest.approx(0.0, abs=1e-9)


def test_geofence_caps_climb_at_the_ceiling() -> None:
    fence = GeofenceBox(max_up_m=2.2)
    fake = FakeVehicle()
    vehicle = flying(fake, SafetyLimits(geofence=fence))  # at 2.0 m
    vehicle.set_velocity_body(VelocityBody(down_m_s=-0.5))
    assert fake.commands[-1].down_m_s == pytest.approx(0.0)
    vehicle.set_velocity_body(VelocityBody(down_m_s=0.3))
    assert fake.commands[-1].down_m_s == pytest.approx(0.3)


def test_a_vehicle_outside_the_fence_is_stopped_with_a_typed_error() -> None:
    fence = GeofenceBox(half_width_east_m=2.0, breach_margin_m=0.5)
    fake = FakeVehicle()
    vehicle = flying(fake, SafetyLimits(geofence=fence))
    fake.position[1] = 2.7
    with pytest.raises(GeofenceBreachError, match=r"0\.70 m outside"):
        vehicle.set_velocity_body(VelocityBody(0.0, -0.5))
    assert fake.commands[-1].is_zero()


def test_takeoff_above_the_fence_is_refused_before_the_backend_sees_it() -> None:
    fake = FakeVehicle()
    vehicle = SafeVehicle(fake, SafetyLimits(geofence=GeofenceBox(max_up_m=3.0)))
    vehicle.arm()
    with pytest.raises(GeofenceBreachError):
        vehicle.takeoff(4.0)
    assert "takeoff" not in fake.calls


def test_watchdog_zeroes_velocity_when_the_controller_goes_silent_in_simulated_time() -> None:
    fake = FakeVehicle()
    vehicle = flying(fake, SafetyLimits(setpoint_timeout_s=0.5, geofence=None))
    vehicle.set_velocity_body(VelocityBody(0.0, 0.5))
    vehicle.sleep(3.0)
    assert vehicle.watchdog_trips == 1
    assert fake.commands[-1].is_zero()
    # 0.5 s of flight at 0.5 m/s plus the lag's tail, instead of 1.5 m without the watchdog.
    assert 0.2 < fake.position[1] < 0.45


def test_watchdog_stays_quiet_while_the_controller_keeps_commanding() -> None:
    fake = FakeVehicle()
    vehicle = flying(fake, SafetyLimits(setpoint_timeout_s=0.5, geofence=None))
    for _ in range(20):
        vehicle.set_velocity_body(VelocityBody(0.0, 0.5))
        vehicle.sleep(0.2)
    assert vehicle.watchdog_trips == 0
    assert fake.position[1] > 1.5


class WallClockFake(FakeVehicle):
    def time_s(self) -> float:
        return time.monotonic()


def test_watchdog_thread_trips_for_a_realtime_vehicle() -> None:
    fake = WallClockFake(realtime=True)
    vehicle = flying(fake, SafetyLimits(setpoint_timeout_s=0.15, geofence=None))
    try:
        vehicle.set_velocity_body(VelocityBody(0.4, 0.0))
        deadline = time.monotonic() + 2.0
        while vehicle.watchdog_trips == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert vehicle.watchdog_trips == 1
        assert fake.commands[-1].is_zero()
    finally:
        vehicle.close()
    assert fake.closed


@pytest.mark.parametrize("interrupt", [RuntimeError("planner crashed"), KeyboardInterrupt()])
def test_flight_guard_holds_then_lands_and_reraises(interrupt: BaseException) -> None:
    fake = FakeVehicle()
    vehicle = flying(fake)
    fake.calls.clear()
    with pytest.raises(type(interrupt)), flight_guard(vehicle):
        vehicle.set_velocity_body(VelocityBody(0.0, 0.3))
        raise interrupt
    assert fake.calls == ["hold", "stop_offboard", "land", "disarm"]
    assert not fake.armed and not fake.in_air


def test_safe_stop_on_the_ground_does_not_land_again() -> None:
    fake = FakeVehicle()
    fake.armed = True
    safe_stop(fake)
    assert "land" not in fake.calls
    assert fake.calls[-1] == "disarm"


def test_safe_stop_of_a_vehicle_down_and_disarmed_already_sends_nothing() -> None:
    """Its own failsafe landed it (after our uplink died, say): nothing to hold, leave or land."""
    fake = FakeVehicle()
    assert safe_stop(fake) == ""
    assert fake.calls == []


def test_safe_stop_keeps_going_when_a_step_fails() -> None:
    class StubbornHold(FakeVehicle):
        def hold(self) -> None:
            raise FlightError("hold()", "COMMAND_DENIED")

    fake = StubbornHold()
    flying(fake)
    safe_stop(fake)
    assert fake.calls[-2:] == ["land", "disarm"]
    assert fake.mode == FlightMode.LAND


def test_limits_are_validated() -> None:
    with pytest.raises(ValueError, match="max_horizontal_speed_m_s"):
        SafetyLimits(max_horizontal_speed_m_s=0.0)
    with pytest.raises(ValueError, match="half_width_east_m"):
        GeofenceBox(half_width_east_m=-1.0)


def test_watchdog_gives_up_quietly_when_offboard_is_already_lost() -> None:
    class LostOffboard(FakeVehicle):
        def set_velocity_body(self, velocity: VelocityBody) -> None:
            if velocity.is_zero() and self.commands:
                raise FlightError("set_velocity_body()", "OFFBOARD_LOST")
            super().set_velocity_body(velocity)

    fake = LostOffboard()
    vehicle = flying(fake, SafetyLimits(setpoint_timeout_s=0.2, geofence=None))
    vehicle.set_velocity_body(VelocityBody(0.0, 0.5))
    vehicle.sleep(1.0)
    assert vehicle.watchdog_trips == 1  # tried once, then stopped trying


def test_limited_is_logged_only_when_a_command_is_limited(caplog: pytest.LogCaptureFixture) -> None:
    fence = GeofenceBox(half_width_north_m=5.0, half_width_east_m=5.0, max_up_m=4.0)
    fake = FakeVehicle(yaw_deg=37.0)  # a heading whose round trip through NED is not exact
    vehicle = flying(fake, SafetyLimits(max_horizontal_speed_m_s=1.0, geofence=fence))
    with caplog.at_level("INFO", logger="flight.safe_vehicle"):
        vehicle.set_velocity_body(VelocityBody(0.1, 0.7, 0.1))  # inside every limit
        assert "limited" not in caplog.text
        assert fake.commands[-1] == VelocityBody(0.1, 0.7, 0.1)  # passed on unchanged, bit for bit
        vehicle.set_velocity_body(VelocityBody(3.0, 4.0))
        assert "limited to" in caplog.text


def test_ctrl_c_sigterm_and_sighup_stop_alike_and_a_second_signal_does_not_abort_the_stop() -> None:
    import os
    import signal

    from flight.signals import StopRequested, stop_signals_as_interrupt

    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        landed = []
        with pytest.raises(StopRequested) as info, stop_signals_as_interrupt():
            try:
                os.kill(os.getpid(), signum)
                time.sleep(1.0)  # the handler raises here
            finally:
                os.kill(os.getpid(), signal.SIGINT)  # a second signal while "landing": ignored
                time.sleep(0.05)
                landed.append(True)
        assert isinstance(info.value, KeyboardInterrupt)
        assert info.value.signal_name == signal.Signals(signum).name
        assert info.value.exit_code == 128 + signum  # the shell's 130, 143, 129
        assert landed == [True]
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL  # handlers restored after the block


@pytest.mark.parametrize("acknowledged", [True, False])
def test_after_a_lost_link_the_guard_still_sends_a_land_and_says_what_came_of_it(acknowledged: bool) -> None:
    class LostLink(FakeVehicle):
        lost = False

        def telemetry(self) -> Telemetry:
            if self.lost:
                raise LinkLostError("telemetry()", 2.1, 2.0)
            return super().telemetry()

        def send_land(self) -> bool:
            self.calls.append("send_land")
            return acknowledged

    fake = LostLink()
    vehicle = flying(fake)
    fake.calls.clear()
    with pytest.raises(LinkLostError) as caught, flight_guard(vehicle):
        fake.lost = True
        vehicle.telemetry()
    assert fake.calls == ["send_land"]  # nothing that waits on telemetry, and the LAND all the same
    message = str(caught.value)
    assert message.startswith("telemetry(): LINK_LOST")
    assert ("acknowledged" in message) == acknowledged
    assert ("could not be confirmed" in message) == (not acknowledged)
