"""The autopilot flying the PyBullet physics: hover, velocity steps, modes, mixer, wind, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _quad_rig import QuadRig

from drone_inspect_core.world_options import WindConfig
from sim_world.physics.autopilot import Autopilot, AutopilotError, AutopilotMode, AutopilotParams
from sim_world.physics.autopilot_control import Mixer
from sim_world.physics.quadrotor import GRAVITY_M_S2, ROTOR_YAW_SIGN, QuadrotorParams
from sim_world.physics.wind import Wind


def _thrust_n(speeds: np.ndarray, prm: QuadrotorParams) -> float:
    return float(sum(prm.kf * w * w for w in speeds))


def test_hover_thrust_equals_weight_and_altitude_holds() -> None:
    with QuadRig() as rig:
        rig.take_off(2.0)
        prm = rig.drone.params
        target_z = rig.autopilot.home_enu_m[2] + 2.0
        heights, thrusts = [], []
        for _ in range(10 * 240):
            rig.step()
            heights.append(rig.state().position_enu_m[2])
            thrusts.append(_thrust_n(rig.drone.rotor_speeds_rad_s, prm))
        heights_arr = np.array(heights)
        assert np.max(np.abs(heights_arr - target_z)) < 0.05
        assert np.mean(thrusts) == pytest.approx(prm.mass_kg * GRAVITY_M_S2, rel=0.01)
        assert thrusts[-1] == pytest.approx(prm.mass_kg * GRAVITY_M_S2, rel=0.01)
        assert rig.autopilot.mode is AutopilotMode.HOLD
        assert np.linalg.norm(rig.state().position_enu_m[:2]) < 0.05


def _right_step_response(yaw_enu_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fly a 0.5 m/s body-right step; return time, body-right speed, yaw change (deg)."""
    with QuadRig(yaw_enu_rad=yaw_enu_rad) as rig:
        rig.take_off(2.0)
        yaw0 = rig.state().yaw_enu_rad
        rig.autopilot.set_velocity_body(0.0, 0.5, 0.0, 0.0)
        right = (math.sin(yaw0), -math.cos(yaw0))  # body right (FRD +y) in ENU
        times, speeds, yaws = [], [], []
        for i in range(3 * 240):
            rig.step()
            state = rig.state()
            v = state.velocity_enu_m_s
            times.append((i + 1) * rig.dt_s)
            speeds.append(v[0] * right[0] + v[1] * right[1])
            yaws.append(math.degrees(state.yaw_enu_rad - yaw0))
        return np.array(times), np.array(speeds), np.array(yaws)


@pytest.mark.parametrize("yaw_enu_rad", [math.pi / 2.0, 0.7])
def test_velocity_step_settles_fast_with_small_overshoot(yaw_enu_rad: float) -> None:
    times, speeds, yaws = _right_step_response(yaw_enu_rad)
    outside = np.nonzero(np.abs(speeds - 0.5) > 0.05)[0]
    settling_s = times[outside[-1] + 1] if outside.size else 0.0
    overshoot = (speeds.max() - 0.5) / 0.5
    assert settling_s < 1.5
    assert overshoot <= 0.20
    assert np.max(np.abs(yaws)) < 2.0
    assert speeds[-1] == pytest.approx(0.5, abs=0.02)


def test_takeoff_hold_land_cycle() -> None:
    with QuadRig() as rig:
        ap = rig.autopilot
        rig.step()
        with pytest.raises(AutopilotError, match="disarmed"):
            ap.takeoff(2.0)
        ap.arm()
        assert ap.armed and ap.landed and ap.mode is AutopilotMode.IDLE
        rig.run_for(0.5)
        assert rig.state().position_enu_m[2] == pytest.approx(rig.drone.resting_height_m, abs=0.005)
        ap.takeoff(3.0)
        assert not ap.landed
        assert rig.run_until(lambda: ap.mode is AutopilotMode.HOLD, timeout_s=8.0)
        home_z = ap.home_enu_m[2]
        rig.run_for(2.0)
        assert rig.state().position_enu_m[2] == pytest.approx(home_z + 3.0, abs=0.1)
        with pytest.raises(AutopilotError, match="in flight"):
            ap.disarm()
        ap.land()
        assert ap.mode is AutopilotMode.LAND
        assert rig.run_until(lambda: ap.landed, timeout_s=12.0)
        assert ap.mode is AutopilotMode.IDLE and ap.armed
        assert rig.state().position_enu_m[2] == pytest.approx(rig.drone.resting_height_m, abs=0.01)
        assert np.linalg.norm(rig.state().position_enu_m[:2]) < 0.1
        ap.disarm()
        assert not ap.armed
        assert rig.autopilot.update(rig.state(), rig.dt_s) == [0.0] * 4


def test_refusals_on_the_ground() -> None:
    ap = Autopilot()
    with pytest.raises(AutopilotError, match="set_velocity_body: refused while disarmed"):
        ap.set_velocity_body(0.5, 0.0, 0.0, 0.0)
    with QuadRig() as rig:
        rig.step()
        rig.autopilot.arm()
        with pytest.raises(AutopilotError, match="hold"):
            rig.autopilot.hold()
        with pytest.raises(AutopilotError, match="altitude_m"):
            rig.autopilot.takeoff(-1.0)
        with pytest.raises(AutopilotError, match="altitude_m"):
            rig.autopilot.takeoff(float("nan"))
        rig.autopilot.land()  # accepted on the ground: nothing to do
        assert rig.autopilot.mode is AutopilotMode.IDLE


def test_velocity_mode_on_the_ground_stays_landed_until_a_climb_then_lifts_off_smoothly() -> None:
    """PX4 accepts OFFBOARD armed on the ground: zero or downward setpoints keep it landed at idle."""
    with QuadRig() as rig:
        ap = rig.autopilot
        rig.step()
        ap.arm()
        ground = rig.state().position_enu_m.copy()
        idle_speed = ap.params.idle_rotor_fraction * rig.drone.params.max_rotor_speed_rad_s
        for setpoint in ((0.0, 0.0, 0.0, 0.0), (0.5, -0.3, 0.4, 20.0)):  # zero; sideways, down, yawing
            ap.set_velocity_ned(*setpoint)
            rig.run_for(1.0)
            assert ap.mode is AutopilotMode.VELOCITY and ap.landed
            assert rig.state().position_enu_m == pytest.approx(ground, abs=0.002)
            assert abs(rig.state().yaw_enu_rad) < 0.01
            assert ap.update(rig.state(), rig.dt_s) == pytest.approx([idle_speed] * 4)
            assert np.linalg.norm(ap.velocity_setpoint) == 0.0

        ap.set_velocity_ned(0.0, 0.0, -1.0, 0.0)  # climb at 1 m/s
        times, climbs, heights = [], [], []
        for i in range(3 * 240):
            rig.step()
            state = rig.state()
            times.append((i + 1) * rig.dt_s)
            climbs.append(state.velocity_enu_m_s[2])
            heights.append(state.position_enu_m[2] - ground[2])
            if i == 0:
                assert ap.landed  # still on the ground while the climb ramps up
        t, climb, height = np.array(times), np.array(climbs), np.array(heights)
        assert not ap.landed and ap.mode is AutopilotMode.VELOCITY
        left_ground_s = t[np.argmax(height > 0.05)]
        assert 0.1 < left_ground_s < 0.6  # ramped, not a jump
        assert np.max(np.diff(climb)) / rig.dt_s < 2.0 * ap.params.takeoff_acc_m_s2  # smooth spool-up
        assert climb.max() < 1.1  # no overshoot of the commanded climb
        assert np.all(np.abs(climb[t >= 1.0] - 1.0) < 0.1)  # tracking the commanded 1 m/s
        assert height[-1] > 2.3
        assert np.linalg.norm(rig.state().position_enu_m[:2] - ground[:2]) < 0.02


def test_velocity_mode_descent_onto_the_ground_is_detected_as_landed() -> None:
    with QuadRig() as rig:
        rig.take_off(1.0, settle_s=0.5)
        ap = rig.autopilot
        ap.set_velocity_body(0.0, 0.0, 0.6, 0.0)  # down onto the ground
        assert not ap.landed
        assert rig.run_until(lambda: ap.landed, timeout_s=5.0)
        assert ap.mode is AutopilotMode.VELOCITY  # still in offboard velocity control, at idle
        assert rig.state().position_enu_m[2] == pytest.approx(rig.drone.resting_height_m, abs=0.01)
        ap.disarm()  # allowed: on the ground
        assert not ap.armed


def test_hold_before_liftoff_returns_to_idle_on_the_ground() -> None:
    with QuadRig() as rig:
        rig.step()
        rig.autopilot.arm()
        rig.autopilot.set_velocity_ned(0.0, 0.0, 0.0, 0.0)
        rig.run_for(0.2)
        rig.autopilot.hold()  # offboard left before lifting off: stays on the ground
        assert rig.autopilot.mode is AutopilotMode.IDLE and rig.autopilot.landed
        rig.autopilot.set_velocity_ned(0.0, 0.0, -0.8, 0.0)
        rig.run_for(0.1)
        rig.autopilot.land()  # still on the ground (ramping up): back to idle, no LAND needed
        assert rig.autopilot.mode is AutopilotMode.IDLE and rig.autopilot.landed
        rig.run_for(0.5)
        assert rig.state().position_enu_m[2] == pytest.approx(rig.drone.resting_height_m, abs=0.005)


def test_hold_locks_the_position_at_entry() -> None:
    with QuadRig() as rig:
        rig.take_off(2.0, settle_s=1.0)
        ap = rig.autopilot
        ap.set_velocity_ned(0.0, 1.0, 0.0, 0.0)  # east
        rig.run_for(2.0)
        entry = rig.state().position_enu_m.copy()
        assert entry[0] > 1.2  # it moved east
        ap.hold()
        rig.run_for(4.0)
        state = rig.state()
        assert state.position_enu_m == pytest.approx(entry, abs=0.05)
        assert np.linalg.norm(state.velocity_enu_m_s) < 0.02
        assert np.linalg.norm(ap.velocity_setpoint) < 0.05


def test_yawspeed_is_clockwise_in_ned() -> None:
    with QuadRig(yaw_enu_rad=math.pi / 2.0) as rig:
        rig.take_off(2.0, settle_s=0.5)
        rig.autopilot.set_velocity_body(0.0, 0.0, 0.0, 30.0)
        rig.run_for(2.0)
        rig.autopilot.set_velocity_body(0.0, 0.0, 0.0, 0.0)
        rig.run_for(1.0)
        # NED yaw 0 → 60° (clockwise from above): ENU yaw 90° → 30°.
        assert math.degrees(rig.state().yaw_enu_rad) == pytest.approx(30.0, abs=3.0)


def test_climb_and_descend_through_ned_down() -> None:
    with QuadRig() as rig:
        rig.take_off(2.0, settle_s=0.5)
        z0 = rig.state().position_enu_m[2]
        rig.autopilot.set_velocity_ned(0.0, 0.0, -0.5, 0.0)  # up
        rig.run_for(2.0)
        assert rig.state().velocity_enu_m_s[2] == pytest.approx(0.5, abs=0.05)
        assert rig.state().position_enu_m[2] - z0 == pytest.approx(0.9, abs=0.15)


def test_mixer_keeps_roll_pitch_and_cuts_yaw_when_saturated() -> None:
    quad = QuadrotorParams()
    mixer = Mixer(AutopilotParams(), quad)
    positions = quad.rotor_positions_flu_m()

    def torques(speeds: list[float]) -> tuple[float, float, float, float]:
        forces = [quad.kf * w * w for w in speeds]
        return (
            sum(forces),
            sum(positions[i][1] * forces[i] for i in range(4)),
            -sum(positions[i][0] * forces[i] for i in range(4)),
            sum(ROTOR_YAW_SIGN[i] * quad.km / quad.kf * forces[i] for i in range(4)),
        )

    # Within the motor range the mix is exact.
    request = (12.0, 0.3, -0.2, 0.02)
    assert torques(mixer.mix(request[0], request[1:])) == pytest.approx(request, rel=1e-9)
    assert not mixer.saturated

    # Near full thrust with a large yaw demand: thrust, roll and pitch kept, yaw cut to what fits.
    speeds = mixer.mix(0.8 * quad.max_thrust_n, (0.1, 0.05, 0.5))
    thrust, roll, pitch, yaw = torques(speeds)
    assert mixer.saturated
    assert (thrust, roll, pitch) == pytest.approx((0.8 * quad.max_thrust_n, 0.1, 0.05), rel=1e-9)
    assert 0.0 < yaw < 0.1
    assert max(speeds) == pytest.approx(quad.max_rotor_speed_rad_s, rel=1e-9)

    # Roll and pitch beyond what full thrust leaves: attitude wins, collective thrust gives way.
    speeds = mixer.mix(0.85 * quad.max_thrust_n, (0.4, 0.3, 0.0))
    thrust, roll, pitch, _ = torques(speeds)
    assert (roll, pitch) == pytest.approx((0.4, 0.3), rel=1e-9)
    assert thrust < 0.8 * quad.max_thrust_n
    assert max(speeds) <= quad.max_rotor_speed_rad_s * (1.0 + 1e-9)


def test_holds_position_in_gusty_wind() -> None:
    wind = WindConfig(mean_enu_m_s=(2.0, 0.0, 0.0), gust_std_m_s=0.5, gust_time_constant_s=2.0)
    with QuadRig(wind=wind, seed=5) as rig:
        rig.take_off(2.0, settle_s=3.0)
        target = rig.state().position_enu_m.copy()
        worst = 0.0
        for _ in range(5 * 24):
            rig.step(10)
            worst = max(worst, float(np.linalg.norm(rig.state().position_enu_m - target)))
        assert worst < 0.3
        assert rig.state().roll_enu_rad != 0.0  # it leans into the wind


def _trajectory(seed: int) -> np.ndarray:
    wind = WindConfig(mean_enu_m_s=(1.0, 0.5, 0.0), gust_std_m_s=0.8, gust_time_constant_s=1.0)
    with QuadRig(wind=wind, seed=seed) as rig:
        rig.take_off(1.5, settle_s=0.5)
        rig.autopilot.set_velocity_body(0.3, -0.2, 0.0, 10.0)
        rows = []
        for _ in range(2 * 24):
            rig.step(10)
            state = rig.state()
            rows.append(
                np.concatenate([state.position_enu_m, state.quaternion_xyzw, rig.drone.rotor_speeds_rad_s])
            )
        return np.array(rows)


def test_same_seed_same_trajectory_in_gusts() -> None:
    first, second, other = _trajectory(11), _trajectory(11), _trajectory(12)
    assert np.array_equal(first, second)
    assert np.max(np.abs(first[:, :3] - other[:, :3])) > 1e-3


def test_wind_statistics_and_query_independence() -> None:
    config = WindConfig(mean_enu_m_s=(1.0, -2.0, 0.0), gust_std_m_s=0.6, gust_time_constant_s=0.5)
    wind = Wind(config, seed=3)
    samples = np.array([wind.velocity_enu_m_s(k * 0.05) for k in range(20_000)])
    assert samples.mean(axis=0) == pytest.approx([1.0, -2.0, 0.0], abs=0.06)
    assert samples.std(axis=0) == pytest.approx([0.6] * 3, rel=0.1)
    lag = round(0.5 / 0.05)  # one time constant: correlation e^-1
    corr = np.corrcoef(samples[:-lag, 0], samples[lag:, 0])[0, 1]
    assert corr == pytest.approx(math.exp(-1.0), abs=0.08)

    fine, coarse = Wind(config, seed=3), Wind(config, seed=3)
    fine_values = [fine.velocity_enu_m_s(k / 240.0) for k in range(2401)]
    for k in range(0, 2401, 8):  # 30 Hz queries see the same wind as 240 Hz queries
        assert np.array_equal(coarse.velocity_enu_m_s(k / 240.0), fine_values[k])
    with pytest.raises(ValueError, match="backwards"):
        coarse.velocity_enu_m_s(1.0)
    assert np.array_equal(Wind(WindConfig(), seed=1).velocity_enu_m_s(3.0), np.zeros(3))


def test_forced_disarm_in_flight_falls_and_reports_landed_at_rest() -> None:
    with QuadRig() as rig:
        rig.take_off(1.0, settle_s=0.5)
        ap = rig.autopilot
        ap.disarm(force=True)
        assert not ap.armed and not ap.landed
        with pytest.raises(AutopilotError, match="not on the ground"):
            ap.arm()
        rig.run_for(0.3)
        assert rig.state().velocity_enu_m_s[2] < -1.0  # rotors stopped: it falls
        assert rig.run_until(lambda: ap.landed, timeout_s=3.0)
        assert rig.state().position_enu_m[2] < 0.1
        ap.arm()
        assert ap.mode is AutopilotMode.IDLE
