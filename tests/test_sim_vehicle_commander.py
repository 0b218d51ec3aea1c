"""PX4's rules in the simulated vehicle, without sockets: modes, params, setpoints, commander.

Time is the fake airframe's simulated time, so these run in milliseconds.
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink
from sim_vehicle_fakes import FakeVehicleModel

from sim_world.vehicle import px4_modes as modes
from sim_world.vehicle.commander import Commander, CommanderConfig, FailsafeStage
from sim_world.vehicle.params import (
    ParamError,
    ParameterStore,
    decode_param_value,
    encode_param_value,
    parse_param_overrides,
)
from sim_world.vehicle.setpoints import (
    VELOCITY_YAWRATE_MASK,
    SetpointFrame,
    SetpointRejected,
    VelocitySetpoint,
    decode_setpoint,
)
from sim_world.vehicle.telemetry import MessageScheduler

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
DENIED = mavlink.MAV_RESULT_DENIED
TEMP_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED


def make(boot_delay_s: float = 2.5, **params: float) -> tuple[FakeVehicleModel, Commander]:
    model = FakeVehicleModel()
    return model, Commander(
        model, ParameterStore(overrides=params), CommanderConfig(arming_boot_delay_s=boot_delay_s)
    )


def run(
    model: FakeVehicleModel, commander: Commander, seconds: float, setpoint: VelocitySetpoint | None = None
):
    """Advance in 10 ms ticks, streaming `setpoint` at 20 Hz when given."""
    for i in range(round(seconds * 100)):
        model.step(1)
        if setpoint is not None and i % 5 == 0:
            commander.on_setpoint(
                VelocitySetpoint(setpoint.frame, setpoint.velocity_m_s, received_s=model.time_s)
            )
        commander.update()


def texts(commander: Commander) -> list[str]:
    return [t for _, t in commander.texts]


def airborne(**params: float) -> tuple[FakeVehicleModel, Commander]:
    model, commander = make(boot_delay_s=0.0, **params)
    assert commander.arm() == ACCEPTED
    assert commander.takeoff() == ACCEPTED
    run(model, commander, 4.0)
    assert commander.mode == modes.AUTO_LOITER
    return model, commander


# ------------------------------------------------------------------------ modes
def test_custom_mode_encoding_matches_px4():
    assert modes.OFFBOARD.custom_mode == 6 << 16 == 393216
    assert modes.AUTO_LOITER.custom_mode == (4 << 16 | 3 << 24) == 50593792
    assert modes.AUTO_TAKEOFF.custom_mode == (4 << 16 | 2 << 24)
    assert modes.AUTO_LAND.custom_mode == (4 << 16 | 6 << 24)
    assert modes.POSCTL.custom_mode == 3 << 16
    for mode in (modes.OFFBOARD, modes.AUTO_LOITER, modes.AUTO_RTL, modes.POSCTL, modes.MANUAL):
        assert modes.Px4Mode.from_custom_mode(mode.custom_mode) == mode
    assert modes.Px4Mode.from_custom_mode(6 << 16 | 3 << 24) == modes.OFFBOARD  # sub ignored outside AUTO
    assert (modes.HOLD.name, modes.OFFBOARD.name) == ("AUTO.LOITER", "OFFBOARD")


def test_do_set_mode_params_as_mavsdk_sends_them():
    assert modes.mode_from_set_mode(129, 6, 0) == modes.OFFBOARD
    assert modes.mode_from_set_mode(129, 4, 3) == modes.HOLD
    assert modes.mode_from_set_mode(1, 4, 6) == modes.AUTO_LAND
    assert modes.mode_from_set_mode(128, 6, 0) is None  # no CUSTOM_MODE_ENABLED flag


# ----------------------------------------------------------------------- params
def test_int_params_travel_bytewise_and_bounds_are_enforced():
    store = ParameterStore()
    spec = store.spec("COM_OBL_RC_ACT")
    raw = encode_param_value(spec, 5)
    assert raw != 5.0 and decode_param_value(spec, raw, mavlink.MAV_PARAM_TYPE_INT32) == 5.0
    assert decode_param_value(spec, 4.0, mavlink.MAV_PARAM_TYPE_REAL32) == 4.0  # plain float accepted
    assert store.set("MIS_TAKEOFF_ALT", 4.0) == 4.0 and store.get("MIS_TAKEOFF_ALT") == 4.0
    with pytest.raises(ParamError, match="MIS_TAKEOFF_ALT"):
        store.set("MIS_TAKEOFF_ALT", 500.0)
    with pytest.raises(ParamError, match="COM_OBL_RC_ACT"):
        store.set("COM_OBL_RC_ACT", 3)  # Return: not simulated
    with pytest.raises(ParamError, match="NOPE"):
        store.get("NOPE")
    assert store.get("MIS_TAKEOFF_ALT") == 4.0


def test_param_overrides_parse_and_name_bad_items():
    assert parse_param_overrides(["COM_OF_LOSS_T=0.5", "MIS_TAKEOFF_ALT = 3"]) == {
        "COM_OF_LOSS_T": 0.5,
        "MIS_TAKEOFF_ALT": 3.0,
    }
    with pytest.raises(ParamError, match="'X'"):
        parse_param_overrides(["X"])
    with pytest.raises(ParamError, match="abc"):
        parse_param_overrides(["COM_OF_LOSS_T=abc"])


# -------------------------------------------------------------------- setpoints
def _sp_msg(frame: int, mask: int = VELOCITY_YAWRATE_MASK, v=(0.1, 0.5, -0.2), yaw_rate=0.3):
    return mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, frame, mask, 0, 0, 0, v[0], v[1], v[2], 0, 0, 0, 0.0, yaw_rate
    )


def test_setpoint_decoding_follows_type_mask_and_frame():
    assert VELOCITY_YAWRATE_MASK == 1479  # what MAVSDK's set_velocity_body sends
    sp = decode_setpoint(_sp_msg(mavlink.MAV_FRAME_BODY_NED), now_s=3.0)
    assert sp.frame is SetpointFrame.BODY_NED and sp.received_s == 3.0
    assert sp.velocity_m_s == pytest.approx((0.1, 0.5, -0.2))
    assert sp.yawspeed_deg_s == pytest.approx(math.degrees(0.3))
    only_vx = decode_setpoint(_sp_msg(mavlink.MAV_FRAME_LOCAL_NED, VELOCITY_YAWRATE_MASK | 0b110000), 0.0)
    assert only_vx.velocity_m_s == pytest.approx((0.1, 0.0, 0.0))
    for frame in (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_LOCAL_OFFSET_NED, mavlink.MAV_FRAME_BODY_FRD):
        with pytest.raises(SetpointRejected, match=r"coordinate frame \d+ unsupported"):
            decode_setpoint(_sp_msg(frame), 0.0)
    with pytest.raises(SetpointRejected, match="only velocity"):  # a position-only setpoint
        decode_setpoint(_sp_msg(mavlink.MAV_FRAME_LOCAL_NED, mask=0b110111111000), 0.0)
    with pytest.raises(SetpointRejected, match="position setpoints unsupported"):  # position + velocity
        decode_setpoint(_sp_msg(mavlink.MAV_FRAME_LOCAL_NED, mask=VELOCITY_YAWRATE_MASK & ~0b111), 0.0)


def test_setpoint_limits_clip_speed_and_yaw_rate():
    sp = VelocitySetpoint(SetpointFrame.BODY_NED, (6.0, 8.0, -9.0), yawspeed_deg_s=200.0)
    out = sp.limited(max_xy_m_s=5.0, max_up_m_s=3.0, max_down_m_s=1.5, max_yaw_deg_s=45.0)
    assert out.velocity_m_s == pytest.approx((3.0, 4.0, -3.0))
    assert out.yawspeed_deg_s == 45.0


# -------------------------------------------------------------------- scheduler
def test_scheduler_intervals_follow_set_message_interval():
    att = mavlink.MAVLINK_MSG_ID_ATTITUDE
    sched = MessageScheduler({att: 50.0}, now_s=0.0)
    assert sched.interval_us(att) == 20_000
    count = sum(att in sched.due(t / 1000) for t in range(0, 1000))
    assert count == 50
    assert sched.set_interval(att, 100_000, now_s=1.0)
    assert sum(att in sched.due(1.0 + t / 1000) for t in range(0, 1000)) == 10
    assert sched.set_interval(att, -1, 2.0) and sched.due(5.0) == [] and sched.interval_us(att) == -1
    assert sched.set_interval(att, 0, 5.0) and sched.interval_us(att) == 20_000
    assert not sched.set_interval(9999, 1000, 5.0) and sched.interval_us(9999) == 0


# -------------------------------------------------------------------- commander
def test_arming_is_temporarily_rejected_until_the_boot_delay_passes():
    model, commander = make(boot_delay_s=2.5)
    model.step(100)  # 1 s after boot
    assert not commander.prearm_ok
    assert commander.arm() == TEMP_REJECTED and not commander.armed
    assert "Resolve system health failures" in texts(commander)[-1]
    model.step(160)  # 2.6 s
    assert commander.prearm_ok and commander.arm() == ACCEPTED and commander.armed
    assert commander.system_status == mavlink.MAV_STATE_ACTIVE
    forced_model, forced = make(boot_delay_s=2.5)
    assert forced.arm(force=True) == ACCEPTED and forced_model.status().armed


def test_offboard_needs_a_fresh_setpoint_stream_and_a_refusal_is_acked_twice():
    model, commander = make(boot_delay_s=0.0)
    assert commander.set_mode(modes.OFFBOARD) == [ACCEPTED, TEMP_REJECTED]
    assert commander.mode == modes.AUTO_LOITER
    assert "Switching to Offboard is currently not available" in texts(commander)
    commander.on_setpoint(VelocitySetpoint(SetpointFrame.BODY_NED, (0, 0, 0), received_s=model.time_s))
    model.step(60)  # 0.6 s: too old for a > 2 Hz stream
    assert commander.set_mode(modes.OFFBOARD) == [ACCEPTED, TEMP_REJECTED]
    commander.on_setpoint(VelocitySetpoint(SetpointFrame.BODY_NED, (0, 0, 0), received_s=model.time_s))
    assert commander.set_mode(modes.OFFBOARD) == [ACCEPTED]
    assert commander.mode == commander.user_mode == modes.OFFBOARD


def test_takeoff_climbs_to_mis_takeoff_alt_then_loiters():
    model, commander = make(boot_delay_s=0.0, MIS_TAKEOFF_ALT=3.0)
    assert commander.takeoff() == DENIED  # disarmed
    assert commander.arm() == ACCEPTED and commander.takeoff() == ACCEPTED
    assert ("takeoff", 3.0) in model.calls and commander.mode == modes.AUTO_TAKEOFF
    run(model, commander, 1.0)
    assert commander.landed_state == mavlink.MAV_LANDED_STATE_TAKEOFF
    run(model, commander, 4.0)
    assert commander.mode == modes.AUTO_LOITER
    assert commander.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR
    assert -model.position[2] == pytest.approx(3.0, abs=0.1)


def test_offboard_flies_setpoints_and_setpoint_loss_fails_safe_then_lands():
    model, commander = airborne(COM_FAIL_ACT_T=2.0)
    right = VelocitySetpoint(SetpointFrame.BODY_NED, (0.0, 0.5, 0.0))
    run(model, commander, 0.3, right)
    assert commander.set_mode(modes.OFFBOARD) == [ACCEPTED]
    east0 = model.position[1]
    run(model, commander, 2.0, right)
    assert model.position[1] - east0 == pytest.approx(0.9, abs=0.1)  # 0.5 m/s × 2 s minus the lag
    assert commander.failsafe is FailsafeStage.NONE
    run(model, commander, 0.95)  # setpoints stop: not yet COM_OF_LOSS_T
    assert commander.mode == modes.OFFBOARD
    run(model, commander, 0.1)
    assert commander.mode == modes.AUTO_LOITER and commander.failsafe is FailsafeStage.HOLD
    assert commander.system_status == mavlink.MAV_STATE_CRITICAL
    assert "Failsafe activated" in texts(commander)
    run(model, commander, 1.0, right)  # setpoints resuming do not bring OFFBOARD back
    assert commander.mode == modes.AUTO_LOITER
    run(model, commander, 1.1)
    assert commander.mode == modes.AUTO_LAND and model.phase == "land"
    run(model, commander, 6.0)  # 2.5 m at 0.7 m/s, then COM_DISARM_LAND = 2 s
    assert not commander.armed
    assert "Landing detected" in texts(commander)
    # As on PX4: back in the mode the client last asked for, so the next arm is refused.
    assert commander.mode == modes.OFFBOARD and commander.system_status == mavlink.MAV_STATE_STANDBY
    assert commander.arm() == DENIED


def test_offboard_loss_action_position_mode_holds_in_posctl():
    model, commander = airborne(COM_FAIL_ACT_T=0.5, COM_OBL_RC_ACT=0)
    commander.on_setpoint(VelocitySetpoint(SetpointFrame.LOCAL_NED, (0.0, 0.0, 0.0), received_s=model.time_s))
    assert commander.set_mode(modes.OFFBOARD) == [ACCEPTED]
    run(model, commander, 1.7)
    assert commander.mode == modes.POSCTL and commander.failsafe is FailsafeStage.ACTION
    assert commander.set_mode(modes.HOLD) == [ACCEPTED]  # the client takes over again
    assert commander.failsafe is FailsafeStage.NONE and commander.system_status == mavlink.MAV_STATE_ACTIVE


def test_disarm_in_air_refused_unless_forced_and_auto_disarm_without_takeoff():
    _, commander = airborne()
    assert commander.disarm() == DENIED and commander.armed
    assert commander.disarm(force=True) == ACCEPTED and not commander.armed
    model2, idle = make(boot_delay_s=0.0)
    assert idle.arm() == ACCEPTED
    run(model2, idle, 9.9)
    assert idle.armed
    run(model2, idle, 0.2)  # COM_DISARM_PRFLT = 10 s
    assert not idle.armed and "no takeoff" in texts(idle)[-1]


def test_land_command_keeps_the_client_mode_but_hold_changes_it():
    model, commander = airborne()
    assert commander.user_mode == modes.AUTO_LOITER  # takeoff completion counts as a mode change
    assert commander.land() == ACCEPTED and commander.mode == modes.AUTO_LAND
    run(model, commander, 6.0)
    assert not commander.armed and commander.mode == modes.AUTO_LOITER
    assert commander.set_mode(modes.MANUAL) == [ACCEPTED, TEMP_REJECTED]  # no RC in the sim
    assert commander.set_mode(modes.AUTO_MISSION) == [ACCEPTED, TEMP_REJECTED]


def test_absolute_yaw_setpoint_turns_towards_the_heading_within_the_rate_limit():
    model, commander = airborne()
    north_facing_east = VelocitySetpoint(
        SetpointFrame.LOCAL_NED, (0.2, 0.0, 0.0), yaw_deg=90.0, received_s=0.0
    )
    commander.on_setpoint(VelocitySetpoint(**{**vars(north_facing_east), "received_s": model.time_s}))
    assert commander.set_mode(modes.OFFBOARD) == [ACCEPTED]
    _, north, east, down, yawspeed = model.calls[-1]
    assert (north, east, down) == (0.2, 0.0, 0.0)
    assert yawspeed == 45.0  # 2/s × 90° error, clipped to MPC_YAWRAUTO_MAX
    for _ in range(60):  # 3 s of a 20 Hz stream
        commander.on_setpoint(VelocitySetpoint(**{**vars(north_facing_east), "received_s": model.time_s}))
        run(model, commander, 0.05)
    assert math.degrees(model.yaw_rad) == pytest.approx(90.0, abs=3.0)
