"""The PX4 bridge's parts that need no PX4: the Earth model, the sensor models, the HIL messages,
the PX4 folder checks and the run's PX4 parameters."""

from __future__ import annotations

import json
import math
import os
import random
import socket
import stat
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from drone_inspect_core.config_files import from_json, to_json
from drone_inspect_core.ports import PortInUseError
from drone_inspect_core.world_options import StartPose, WindConfig
from sim_world.physics.quadrotor import GRAVITY_M_S2, QuadrotorParams
from sim_world.px4_bridge.geodesy import HomePoint, magnetic_field_ned_gauss, pressure_hpa, temperature_c
from sim_world.px4_bridge.instances import px4_instance
from sim_world.px4_bridge.link import SimulatorServer
from sim_world.px4_bridge.messages import (
    ACCEL_BITS,
    BARO_BITS,
    GYRO_BITS,
    MAG_BITS,
    ActuatorCommand,
    HilEncoder,
    RotorMapping,
    actuator_command,
    px4_airframe_params,
    quaternion_wxyz,
)
from sim_world.px4_bridge.px4_process import (
    Px4FolderError,
    Px4Options,
    Px4Ports,
    Px4Process,
    check_px4_dir,
    find_px4_dir,
    speed_scaled_timeouts,
)
from sim_world.px4_bridge.run import Px4SimConfig
from sim_world.px4_bridge.sensors import BaroReading, ImuReading, SensorNoise, SensorSuite, Truth
from sim_world.vehicle.telemetry import DEFAULT_RATES_HZ

ZURICH = HomePoint()


def _yaw_rotation(yaw_rad: float) -> np.ndarray:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _truth(rotation: np.ndarray, acceleration=(0.0, 0.0, 0.0), position=(0.0, 0.0, 0.0), t=1.0) -> Truth:
    return Truth(
        time_s=t,
        position_ned_m=np.array(position, float),
        velocity_ned_m_s=np.zeros(3),
        acceleration_ned_m_s2=np.array(acceleration, float),
        rotation_ned_frd=rotation,
        rates_frd_rad_s=np.array([0.1, -0.2, 0.3]),
    )


def test_world_magnetic_model_at_px4s_home_matches_published_values() -> None:
    field = magnetic_field_ned_gauss(
        ZURICH.latitude_deg, ZURICH.longitude_deg, ZURICH.altitude_amsl_m, 2025.5
    )
    # NOAA's WMM2025 for Zurich: declination ~3.5° E, inclination ~63.5°, ~48,300 nT.
    assert 2.5 < field.declination_deg < 4.5
    assert 62.5 < field.inclination_deg < 64.5
    assert 0.47 < field.strength_gauss < 0.49
    south = magnetic_field_ned_gauss(-33.9, 151.2, 0.0, 2025.5)  # Sydney: field points up, east declination
    assert south.inclination_deg < -50.0


def test_standard_atmosphere() -> None:
    assert pressure_hpa(0.0) == pytest.approx(1013.25)
    assert pressure_hpa(488.0) == pytest.approx(956.0, abs=0.5)  # 1 hPa ≈ 8.4 m near sea level
    assert pressure_hpa(100.0) - pressure_hpa(101.0) == pytest.approx(0.12, abs=0.005)
    assert temperature_c(0.0) == pytest.approx(15.0)


def test_a_level_drone_at_rest_measures_minus_g_on_body_down_and_the_field_rotated_by_its_heading() -> None:
    field = magnetic_field_ned_gauss(
        ZURICH.latitude_deg, ZURICH.longitude_deg, ZURICH.altitude_amsl_m, 2025.5
    )
    sensors = SensorSuite(ZURICH, field, SensorNoise().scaled(0.0), seed=0)
    east = _yaw_rotation(math.pi / 2)  # heading east: body forward = NED east
    imu = sensors.imu(_truth(east))
    np.testing.assert_allclose(imu.accel_frd_m_s2, [0.0, 0.0, -9.80665], atol=1e-9)
    np.testing.assert_allclose(imu.gyro_frd_rad_s, [0.1, -0.2, 0.3], atol=1e-12)
    mag = sensors.mag(_truth(east))
    # Facing east, the field's north component points to the body's left (-right), east to forward.
    np.testing.assert_allclose(mag, [field.east_gauss, -field.north_gauss, field.down_gauss], atol=1e-9)


def test_accelerometer_adds_kinematic_acceleration_in_the_body_frame() -> None:
    field = magnetic_field_ned_gauss(0.0, 0.0, 0.0, 2025.5)
    sensors = SensorSuite(ZURICH, field, SensorNoise().scaled(0.0), seed=0)
    imu = sensors.imu(_truth(np.eye(3), acceleration=(1.0, 0.0, -2.0)))  # north, facing north, climbing
    np.testing.assert_allclose(imu.accel_frd_m_s2, [1.0, 0.0, -2.0 - 9.80665], atol=1e-9)


def test_noise_has_the_configured_spread_and_repeats_for_a_seed() -> None:
    field = magnetic_field_ned_gauss(0.0, 0.0, 0.0, 2025.5)
    noise = SensorNoise(accel_bias_m_s2=0.0, accel_bias_walk=0.0)
    a = SensorSuite(ZURICH, field, noise, seed=3)
    b = SensorSuite(ZURICH, field, noise, seed=3)
    samples = np.array([a.imu(_truth(np.eye(3), t=0.004 * i)).accel_frd_m_s2 for i in range(1, 4001)])
    expected_std = noise.accel_noise_density / math.sqrt(0.004)
    assert samples[:, 0].std() == pytest.approx(expected_std, rel=0.1)
    assert abs(samples[:, 2].mean() + 9.80665) < 0.01
    again = np.array([b.imu(_truth(np.eye(3), t=0.004 * i)).accel_frd_m_s2 for i in range(1, 4001)])
    np.testing.assert_array_equal(samples, again)


def test_gps_and_baro_follow_the_truth_from_home() -> None:
    field = magnetic_field_ned_gauss(0.0, 0.0, 0.0, 2025.5)
    sensors = SensorSuite(ZURICH, field, SensorNoise().scaled(0.0), seed=0)
    up_north = _truth(np.eye(3), position=(111.2, 0.0, -10.0))  # ~0.001° north, 10 m up
    gps = sensors.gps(up_north)
    assert gps.latitude_deg - ZURICH.latitude_deg == pytest.approx(0.001, rel=0.01)
    assert gps.longitude_deg == pytest.approx(ZURICH.longitude_deg)
    assert gps.altitude_amsl_m == pytest.approx(ZURICH.altitude_amsl_m + 10.0)
    baro = sensors.baro(up_north)
    assert baro.pressure_hpa == pytest.approx(pressure_hpa(ZURICH.altitude_amsl_m + 10.0))


def test_hil_messages_decode_as_px4_reads_them() -> None:
    encoder = HilEncoder()
    parser = mavlink.MAVLink(None)
    field = magnetic_field_ned_gauss(0.0, 0.0, 0.0, 2025.5)
    sensors = SensorSuite(ZURICH, field, SensorNoise().scaled(0.0), seed=0)
    truth = _truth(np.eye(3))
    imu_only = parser.parse_buffer(encoder.hil_sensor(123, sensors.imu(truth), None, None))[0]
    assert imu_only.get_type() == "HIL_SENSOR" and imu_only.time_usec == 123
    assert imu_only.fields_updated == ACCEL_BITS | GYRO_BITS and imu_only.id == 0
    assert imu_only.zacc == pytest.approx(-9.80665, abs=1e-5)
    full = parser.parse_buffer(
        encoder.hil_sensor(456, sensors.imu(truth), sensors.mag(truth), sensors.baro(truth))
    )[0]
    assert full.fields_updated == ACCEL_BITS | GYRO_BITS | MAG_BITS | BARO_BITS
    assert full.abs_pressure == pytest.approx(pressure_hpa(ZURICH.altitude_amsl_m), abs=1e-3)
    gps = parser.parse_buffer(encoder.hil_gps(789, sensors.gps(truth)))[0]
    assert gps.fix_type == 3 and gps.lat == round(ZURICH.latitude_deg * 1e7)
    assert gps.alt == round(ZURICH.altitude_amsl_m * 1000) and gps.cog == 65535  # at rest: unknown course
    state = parser.parse_buffer(encoder.hil_state_quaternion(1, truth, (1.0, 2.0, 3.0)))[0]
    assert list(state.attitude_quaternion) == pytest.approx([1.0, 0.0, 0.0, 0.0])
    assert state.zacc == pytest.approx(-1000, abs=1)  # mG


def test_quaternion_of_a_rotation_matrix() -> None:
    q = quaternion_wxyz(_yaw_rotation(math.pi / 2))
    assert q == pytest.approx([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])
    flip = np.diag([1.0, -1.0, -1.0])  # 180° about x
    assert [abs(v) for v in quaternion_wxyz(flip)] == pytest.approx([0.0, 1.0, 0.0, 0.0])


def _payload(message: mavlink.MAVLink_message) -> bytes:
    """The payload of `message` as it crosses the link (MAVLink 2: trailing zeros cut)."""
    frame = message.pack(mavlink.MAVLink(None, srcSystem=1, srcComponent=1))
    return frame[10:-2]


def test_actuator_controls_become_rotor_speeds_only_while_armed() -> None:
    mapping = RotorMapping(max_rad_s=1100.0)
    armed = mavlink.MAVLink_hil_actuator_controls_message(
        5, [0.0, 0.5, 1.0, float("nan")] + [0.0] * 12, mavlink.MAV_MODE_FLAG_SAFETY_ARMED | 1, 1
    )
    command = actuator_command(_payload(armed))
    assert command.armed and command.lockstep and command.time_usec == 5
    assert mapping.rotor_speeds(command) == pytest.approx([100.0, 600.0, 1100.0, 100.0])  # NaN: idle
    disarmed = mavlink.MAVLink_hil_actuator_controls_message(6, [0.7] * 16, 1, 1)
    assert mapping.rotor_speeds(actuator_command(_payload(disarmed))) == [0.0] * 4
    assert mapping.rotor_speeds(None) == [0.0] * 4
    idle = actuator_command(_payload(mavlink.MAVLink_hil_actuator_controls_message(7, [0.0] * 16, 0, 0)))
    assert idle == ActuatorCommand(7, False, (0.0, 0.0, 0.0, 0.0), False)  # a payload cut to one byte


def test_hil_sensor_is_packed_byte_for_byte_as_pymavlink_packs_it() -> None:
    rng = np.random.default_rng(5)
    encoder = HilEncoder()
    for seq in range(300):  # the sequence counter wraps at 256
        imu = ImuReading(rng.normal(0.0, 5.0, 3), rng.normal(0.0, 1.0, 3))
        mag = rng.normal(0.0, 0.5, 3) if seq % 2 else None
        baro = BaroReading(*rng.uniform(0.0, 1000.0, 3)) if seq % 3 else None
        if seq % 7 == 0:  # all zero but the time: a payload MAVLink 2 cuts short
            imu = ImuReading(np.zeros(3), np.zeros(3))
        ours = encoder.hil_sensor(1000 * seq, imu, mag, baro)
        reference = mavlink.MAVLink(None, srcSystem=1, srcComponent=51)
        reference.seq = seq % 256
        decoded = mavlink.MAVLink(None).parse_buffer(ours)[0]
        assert ours == decoded.pack(reference), seq


@pytest.mark.parametrize(
    "quad", [QuadrotorParams(), QuadrotorParams(mass_kg=1.4, max_rotor_speed_rad_s=1300.0)]
)
def test_px4_is_told_the_hover_thrust_of_the_quad_it_flies(quad: QuadrotorParams) -> None:
    hover = px4_airframe_params(quad)["MPC_THR_HOVER"]
    [rotor_rad_s, *_] = RotorMapping.for_quad(quad).rotor_speeds(ActuatorCommand(0, True, (hover,) * 4, True))
    assert 4 * quad.kf * rotor_rad_s**2 == pytest.approx(
        quad.mass_kg * GRAVITY_M_S2, rel=0.005
    )  # holds it up


def _fake_px4_dir(root: Path, airframe: bool = True) -> Path:
    (root / "bin").mkdir(parents=True)
    binary = root / "bin" / "px4"
    binary.write_text("#!/bin/sh\nexit 0\n")
    binary.chmod(binary.stat().st_mode | stat.S_IXUSR)
    (root / "bin" / "px4-param").write_text("px4")  # a link flattened by a copy
    (root / "bin" / "px4-alias.sh").write_text("#!/bin/sh\n")
    (root / "etc" / "init.d-posix" / "airframes").mkdir(parents=True)
    (root / "etc" / "init.d-posix" / "rcS").write_text("#!/bin/sh\n")
    if airframe:
        (root / "etc" / "init.d-posix" / "airframes" / "10016_none_iris").write_text("#!/bin/sh\n")
    return root


def test_px4_folder_errors_name_what_is_wrong(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(Px4FolderError, match="is not a folder"):
        check_px4_dir(tmp_path / "missing")
    with pytest.raises(Px4FolderError, match="no bin/px4"):
        check_px4_dir(tmp_path)
    old = _fake_px4_dir(tmp_path / "old", airframe=False)
    with pytest.raises(Px4FolderError, match="no airframe 10016"):
        check_px4_dir(old)
    good = _fake_px4_dir(tmp_path / "good")
    assert check_px4_dir(good) == good.resolve()
    monkeypatch.delenv("PX4_SITL_DIR", raising=False)
    with pytest.raises(Px4FolderError, match="pass --px4 DIR or set PX4_SITL_DIR"):
        find_px4_dir(None)
    monkeypatch.setenv("PX4_SITL_DIR", str(tmp_path / "nowhere"))
    with pytest.raises(Px4FolderError, match=r"\$PX4_SITL_DIR: .*nowhere is not a folder"):
        find_px4_dir(None)
    assert find_px4_dir(good) == good.resolve()  # --px4 wins over the environment


def test_px4_run_gets_links_its_params_and_a_private_folder(tmp_path: Path) -> None:
    px4_dir = _fake_px4_dir(tmp_path / "px4")
    options = Px4Options(px4_dir, instance=3, system_id=42, params={"MPC_XY_VEL_MAX": 1.5}, speed_factor=4.0)
    process = Px4Process(options).start()
    try:
        links = process.workdir / "bin"
        assert os.readlink(links / "px4-param") == str(px4_dir / "bin" / "px4")  # a real link again
        script = (links / "px4-rc.params").read_text()
        assert "param set MAV_SYS_ID 42" in script
        assert "param set MPC_XY_VEL_MAX 1.5" in script
        assert "param set COM_OF_LOSS_T 4" in script  # 4× faster than real time: 4× longer timeouts
        assert "param set NAV_MC_ALT_RAD 0.1" in script  # a 0.5 m takeoff climbs to 0.5 m, not to liftoff
        assert "param set SDLOG_MODE -1" in script  # no .ulg written where nobody keeps it
    finally:
        process.close()
    assert not process.workdir.exists()


def test_px4_logs_its_flights_where_they_are_kept_and_a_runs_own_params_win(tmp_path: Path) -> None:
    px4_dir = _fake_px4_dir(tmp_path / "px4")
    for options, expected in (
        (Px4Options(px4_dir, keep_logs_in=tmp_path / "logs"), None),
        (Px4Options(px4_dir, instance=1, params={"SDLOG_MODE": 0}), "param set SDLOG_MODE 0"),
    ):
        process = Px4Process(options).start()
        try:
            lines = (process.workdir / "bin" / "px4-rc.params").read_text().splitlines()
            assert [line for line in lines if "SDLOG_MODE" in line] == ([expected] if expected else [])
        finally:
            process.close()


def test_speed_scaled_timeouts() -> None:
    assert speed_scaled_timeouts(None) == {} and speed_scaled_timeouts(1.0) == {}
    assert speed_scaled_timeouts(2.0)["COM_DL_LOSS_T"] == 20.0
    with pytest.raises(ValueError, match="instance"):
        Px4Options(Path("/x"), instance=10)
    with pytest.raises(ValueError, match="not valid"):
        Px4Options(Path("/x"), params={"bad name": 1.0})


def test_simulator_config_survives_json(tmp_path: Path) -> None:
    config = Px4SimConfig(
        px4_dir=tmp_path,
        instance=2,
        seed=5,
        start_offset=StartPose(right_m=0.1, up_m=-0.2, distance_m=2.0, yaw_deg=3.0),
        system_id=99,
        params={"COM_DISARM_LAND": 1.0},
        wind=WindConfig(mean_enu_m_s=(0.5, 0.0, 0.0), gust_std_m_s=0.3),
        duration_s=12.0,
    )
    assert from_json(Px4SimConfig, json.loads(json.dumps(to_json(config)))) == config
    with pytest.raises(ValueError, match="instance"):
        Px4SimConfig(px4_dir=tmp_path, instance=12)


def test_a_run_that_chooses_px4s_ports_runs_one_link_on_them(tmp_path: Path) -> None:
    options = Px4Options(_fake_px4_dir(tmp_path / "px4"), ports=Px4Ports(41001, 41002, 41003))
    process = Px4Process(options).start()
    try:
        links = process.workdir / "bin"
        assert "simulator_mavlink start -c 41001" in (links / "px4-rc.simulator").read_text()
        script = (links / "px4-rc.mavlink").read_text()
        starts = [line for line in script.splitlines() if line.startswith("mavlink start")]
        assert starts == ["mavlink start -x -u 41002 -r 4000000 -f -m onboard -o 41003"]  # no GCS link
        assert "mavlink stream -r 10 -s HEARTBEAT -u 41002" in script.splitlines()  # modes seen in 0.1 s
        assert "mavlink stream -r 10 -s EXTENDED_SYS_STATE -u 41002" in script.splitlines()  # landings too
        assert "mavlink stream -r 0 -s HIGHRES_IMU -u 41002" in script.splitlines()  # nobody reads it
        for msg_id, rate_hz in DEFAULT_RATES_HZ.items():  # what the sim-vehicle streams, at its rates
            if rate_hz > 0:
                name = mavlink.mavlink_map[msg_id].msgname
                assert f"mavlink stream -r {rate_hz:g} -s {name} -u 41002" in script.splitlines()
    finally:
        process.close()
    assert not (Px4Process(Px4Options(tmp_path / "px4")).workdir / "bin" / "px4-rc.mavlink").exists()


def test_auto_skips_an_instance_whose_port_another_program_holds_and_a_fixed_one_names_it() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as held:
        held.bind(("0.0.0.0", 0))
        port = held.getsockname()[1]
        with px4_instance("auto") as lowest:  # the lowest instance nobody holds right now
            pass

        def ports(instance: int) -> list[tuple[str, int, str]]:
            return [("udp", port, "a port held by someone else")] if instance == lowest else []

        with px4_instance("auto", ports) as instance:  # type: ignore[arg-type]
            assert instance != lowest
        taken = f"UDP port {port} \\(a port held by someone else\\)"
        with pytest.raises(PortInUseError, match=taken), px4_instance(lowest, ports):  # type: ignore[arg-type]
            pass


def test_the_simulator_link_finds_every_good_frame_among_junk_in_any_chunking() -> None:
    rng = random.Random(3)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    sent: list[tuple[int, bytes]] = []
    stream = b""
    for i in range(400):
        message = rng.choice(
            [
                mavlink.MAVLink_hil_actuator_controls_message(i, [rng.random()] * 4 + [0.0] * 12, 129, 1),
                mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3),
                mavlink.MAVLink_statustext_message(6, f"text {i}".encode()),
            ]
        )
        frame = message.pack(mav)
        sent.append((message.get_msgId(), frame[10:-2]))
        junk = rng.choice([b"", bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40))), b"\xfd\x05"])
        corrupt = bytearray(frame)
        corrupt[rng.randrange(10, len(corrupt))] ^= 0xFF  # a frame whose CRC fails: skipped, not its length
        stream += frame + junk + (bytes(corrupt) if rng.random() < 0.2 else b"")
    with SimulatorServer("127.0.0.1", 0) as server, socket.create_connection(server.address) as px4:
        server.accept(5.0)
        got = []
        at = 0
        while at < len(stream):
            size = rng.randrange(1, 300)
            px4.sendall(stream[at : at + size])
            at += size
            got += server.receive(1.0)
        while len(got) < len(sent) and (more := server.receive(0.5)):
            got += more
    # Junk can hold a frame-like run whose CRC happens to pass only with odds of 1 in 65536 per candidate.
    assert [(f.msg_id, f.payload) for f in got] == sent
    assert server.bad_frames > 0
