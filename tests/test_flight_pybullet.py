"""The PyBullet backend: PX4's client-visible rules, frames, determinism, a move through the safety layer."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from flight.errors import CommandDeniedError
from flight.pybullet_backend import PyBulletVehicle
from flight.scenario import MoveFlight, fly_move
from flight.types import FlightMode, VelocityBody


@pytest.fixture
def vehicle() -> Iterator[PyBulletVehicle]:
    with PyBulletVehicle.create(seed=3) as v:
        v.connect()
        v.wait_ready()
        yield v


def test_refusals_match_px4(vehicle: PyBulletVehicle) -> None:
    with pytest.raises(CommandDeniedError, match=r"takeoff\(\): COMMAND_DENIED"):
        vehicle.takeoff(2.0)
    vehicle.set_velocity_body(VelocityBody())
    with pytest.raises(CommandDeniedError, match="not armed"):
        vehicle.start_offboard()
    vehicle.arm()
    vehicle.takeoff(1.5)
    with pytest.raises(CommandDeniedError, match=r"disarm\(\)"):
        vehicle.disarm()  # in the air


def test_offboard_needs_a_setpoint_first(vehicle: PyBulletVehicle) -> None:
    vehicle.arm()
    vehicle.takeoff(1.5)
    with pytest.raises(CommandDeniedError, match="NO_SETPOINT_SET"):
        vehicle.start_offboard()
    vehicle.set_velocity_body(VelocityBody())
    vehicle.start_offboard()
    assert vehicle.telemetry().flight_mode == FlightMode.OFFBOARD


def test_takeoff_reaches_altitude_in_ned_facing_north(vehicle: PyBulletVehicle) -> None:
    vehicle.arm()
    vehicle.takeoff(2.0)
    t = vehicle.telemetry()
    assert t.in_air and t.armed
    assert -t.position_ned.down_m == pytest.approx(2.0, abs=0.3)
    assert t.attitude.yaw_deg == pytest.approx(0.0, abs=2.0)  # facing the wall, north
    assert t.position_ned.horizontal_m < 0.05


def test_one_move_flight_is_deterministic_and_ends_landed() -> None:
    flight = MoveFlight(right_m=-0.4, forward_m=0.2, speed_m_s=0.3, takeoff_alt_m=2.0)
    results = []
    for _ in range(2):
        with PyBulletVehicle.create(seed=5) as v:
            results.append(fly_move(v, flight))
            t = v.telemetry()
            assert not t.armed and not t.in_air
            assert v.time_s() > results[-1].timings.landed_s  # simulated time ran ahead of the wall clock
    first, second = (r.move.displacement for r in results)
    assert first == second
    assert first.right_m == pytest.approx(-0.4, abs=0.1)
    assert first.forward_m == pytest.approx(0.2, abs=0.1)
    assert first.east_m == pytest.approx(first.right_m, abs=1e-6)  # facing north: right is east


def test_move_command_flies_the_in_process_backend(capsys: pytest.CaptureFixture[str]) -> None:
    from dronectl.move_cmd import main

    assert main(["--vehicle", "sim", "--right-m", "0.3", "--takeoff-alt", "1.5"]) == 0
    out = capsys.readouterr().out
    achieved = next(line for line in out.splitlines() if line.startswith("achieved:"))
    assert float(achieved.split()[2]) == pytest.approx(0.3, abs=0.1)


def test_move_command_explains_a_bad_url(capsys: pytest.CaptureFixture[str]) -> None:
    from dronectl.move_cmd import main

    assert main(["--vehicle", "udpin://localhost:14540", "--right-m", "0.5"]) == 1
    assert "udpin://127.0.0.1:14540" in capsys.readouterr().err


def test_move_command_flies_only_the_axes_given(monkeypatch: pytest.MonkeyPatch) -> None:
    """`--forward-m 0.5` is a forward move only (it used to add the default 0.5 m right)."""
    import dronectl.move_cmd as move_cmd

    flown = []
    monkeypatch.setattr(move_cmd, "fly_move", lambda vehicle, flight, limits: flown.append(flight) or 1 / 0)
    with pytest.raises(ZeroDivisionError):  # stop right after the flight plan was handed over
        move_cmd.main(["--vehicle", "sim", "--forward-m", "0.5"])
    assert (flown[0].forward_m, flown[0].right_m, flown[0].down_m) == (0.5, 0.0, 0.0)
    with pytest.raises(SystemExit):  # no move at all: a usage error, not a silent default
        move_cmd.main(["--vehicle", "sim"])


def test_sleep_never_ends_early_and_always_advances_the_clock(vehicle: PyBulletVehicle) -> None:
    dt = vehicle.world.dt_s
    start = vehicle.time_s()
    vehicle.sleep(dt * 1e-6)  # a sliver: still one whole step, never zero (no busy loop for callers)
    assert vehicle.time_s() == pytest.approx(start + dt)
    vehicle.sleep(2.5 * dt)  # rounded up to whole steps
    assert vehicle.time_s() == pytest.approx(start + 4 * dt)
    vehicle.sleep(10 * dt)  # whole steps are exact
    assert vehicle.time_s() == pytest.approx(start + 14 * dt)
    vehicle.sleep(0.0)
    assert vehicle.time_s() == pytest.approx(start + 14 * dt)
