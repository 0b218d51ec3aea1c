"""MAVLink 2 signing: key files, the verifier, a signed sim-vehicle and the relay that signs for MAVSDK.

The sim-vehicle runs the real PyBullet world behind real UDP on loopback; the peers are plain sockets
and the pymavlink test client, signing with the run's key, another key, or not at all.
"""

from __future__ import annotations

import base64
import contextlib
import socket
import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M
from sim_vehicle_client import MavlinkTestClient, served_vehicle

from drone_inspect_core.signing import (
    FrameSigner,
    FrameVerifier,
    SigningKey,
    SigningKeyError,
    is_signed,
    signing_timestamp_now,
)
from flight.relay import MavlinkRelay
from sim_world.rendering.camera import CameraConfig
from sim_world.vehicle.commander import CommanderConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.server import SimVehicle
from sim_world.vehicle.world_model import WorldVehicleModel
from sim_world.world import World, WorldConfig

ARM = M.MAV_CMD_COMPONENT_ARM_DISARM
SECRET = bytes(range(1, 33))


# ------------------------------------------------------------------------------------------ keys
def test_a_key_file_holds_32_bytes_as_hex_or_base64(tmp_path: Path) -> None:
    hex_file, b64_file = tmp_path / "hex.key", tmp_path / "b64.key"
    hex_file.write_text(f"# the drone's key\n{SECRET.hex().upper()}\n\n")
    b64_file.write_text(base64.b64encode(SECRET).decode() + "\n")
    assert SigningKey.load(hex_file).secret == SECRET == SigningKey.load(b64_file).secret
    assert SECRET.hex() not in repr(SigningKey.load(hex_file))


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("", "found 0 lines"),
        (base64.b64encode(SECRET[:31]).decode(), "got 31"),
        ("key!" * 16, "not 64 hex digits and not base64"),
        ("00" * 32, "all-zero"),
        (f"{SECRET.hex()}\n{SECRET.hex()}", "found 2 lines"),
    ],
)
def test_a_bad_key_file_is_named_with_what_is_wrong(tmp_path: Path, text: str, fragment: str) -> None:
    path = tmp_path / "bad.key"
    path.write_text(text)
    with pytest.raises(SigningKeyError, match=fragment) as caught:
        SigningKey.load(path)
    assert str(path) in str(caught.value)
    with pytest.raises(SigningKeyError, match="does not exist"):
        SigningKey.load(tmp_path / "missing.key")
    with pytest.raises(SigningKeyError, match="is a folder"):
        SigningKey.load(tmp_path)


# -------------------------------------------------------------------------------------- verifier
def _frame(key: SigningKey, sender: tuple[int, int] = (245, 190)) -> bytes:
    heartbeat = M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(M.MAVLink(None, *sender))
    return FrameSigner(key).sign(M.MAVLink(None).parse_buffer(heartbeat)[0])


def test_the_verifier_takes_a_fresh_frame_once_and_nothing_else() -> None:
    key = SigningKey(SECRET)
    frame = _frame(key)
    assert is_signed(frame)
    verifier = FrameVerifier(key)
    assert verifier.verify(frame)
    assert not verifier.verify(frame)  # a replay
    assert not FrameVerifier(SigningKey.generate()).verify(_frame(key))  # another key
    unsigned = M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(M.MAVLink(None, 245, 190))
    assert not verifier.verify(unsigned)
    assert (verifier.accepted, verifier.rejected) == (1, 2)


def test_a_forged_frame_from_the_future_does_not_lock_out_the_real_stream() -> None:
    """pymavlink records a new stream's timestamp before checking the signature: one forged frame
    with a far-future timestamp would make every genuine frame "old". Ours checks first."""
    key = SigningKey(SECRET)
    forged = bytearray(_frame(key, sender=(245, 190)))
    future = signing_timestamp_now() + 10**12
    forged[-12:-6] = future.to_bytes(6, "little")  # the signature no longer matches
    verifier = FrameVerifier(key)
    assert not verifier.verify(bytes(forged))
    assert verifier.verify(_frame(key, sender=(245, 190)))


# ---------------------------------------------------------------------------------- sim-vehicle
def signed_vehicle(
    key: SigningKey,
) -> contextlib.AbstractContextManager[tuple[MavlinkTestClient, SimVehicle]]:
    """A signed mission sim-vehicle streaming to a test client (its controller, which signs)."""
    return served_vehicle(adopt_client=False, signing_key=key)


def _acks(client: MavlinkTestClient, command: int, seconds: float = 0.6) -> list[int]:
    t0 = time.monotonic()
    client.send(M.MAVLink_command_long_message(0, 1, command, 0, 1, 0, 0, 0, 0, 0, 0))
    time.sleep(seconds)
    return [r.msg.result for r in client.since(t0, "COMMAND_ACK") if r.msg.command == command]


def test_a_signed_vehicle_obeys_only_its_key_and_signs_what_it_sends() -> None:
    key = SigningKey.generate()
    with signed_vehicle(key) as (client, vehicle):
        heartbeat = client.wait_for("HEARTBEAT", 2.0, after=0.0)
        assert is_signed(bytes(heartbeat.get_msgbuf()))
        assert _acks(client, ARM) == []  # unsigned, from the controller's own address: ignored
        client.sign_with(SigningKey.generate())
        assert _acks(client, ARM) == []  # signed with another key: ignored
        assert not vehicle.commander.armed
        client.sign_with(key)
        assert _acks(client, ARM) == [M.MAV_RESULT_ACCEPTED]
        assert vehicle.commander.armed
        stats = vehicle.stats()
        assert stats.messages_unsigned == 2
        assert vehicle.senders() == {"245/190": stats.messages_in}


def test_unsigned_message_intervals_and_parameters_change_nothing() -> None:
    key = SigningKey.generate()
    with signed_vehicle(key) as (client, vehicle):
        silence = M.MAVLink_command_long_message(
            0, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_ATTITUDE, -1, 0, 0, 0, 0, 0
        )
        client.send(silence)
        client.send(M.MAVLink_param_set_message(0, 1, b"MPC_XY_VEL_MAX", 0.0, M.MAV_PARAM_TYPE_REAL32))
        time.sleep(0.3)
        assert client.rate_hz("ATTITUDE", 0.5) > 20
        assert vehicle.params.changed() == {}


# ------------------------------------------------------------------------------------------ relay
def _socket() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(2.0)
    return sock


def test_the_relay_signs_for_its_client_and_passes_on_only_signed_telemetry(tmp_path: Path) -> None:
    key = SigningKey.generate()
    vehicle_mav = M.MAVLink(None, 42, 1)
    vehicle_mav.signing.secret_key, vehicle_mav.signing.sign_outgoing = key.secret, True
    vehicle_mav.signing.timestamp = signing_timestamp_now()
    heartbeat = M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, 0, 0, 3, 3)
    with (
        _socket() as vehicle,
        _socket() as client,
        MavlinkRelay(
            0, client.getsockname()[1], tmp_path / "f.tlog", vehicle_system_id=42, signing_key=key
        ) as relay,
    ):
        listen = relay.listen_address
        vehicle.sendto(heartbeat.pack(M.MAVLink(None, 42, 1)), listen)  # unsigned: not the vehicle
        time.sleep(0.2)
        assert relay.vehicle_address is None and relay.unsigned_dropped == 1
        signed = bytes(heartbeat.pack(vehicle_mav))
        vehicle.sendto(signed, listen)
        assert client.recvfrom(65535)[0] == signed
        command = M.MAVLink_command_long_message(42, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
        client.sendto(command.pack(M.MAVLink(None, 245, 190)), relay._client_sock.getsockname())
        sent = vehicle.recvfrom(65535)[0]
        assert is_signed(sent) and FrameVerifier(key).verify(sent)
        parsed = M.MAVLink(None).parse_buffer(sent)[0]
        assert (parsed.get_type(), parsed.get_srcSystem(), parsed.get_srcComponent()) == (
            "COMMAND_LONG",
            245,
            190,
        )
    log = mavutil.mavlink_connection(str(tmp_path / "f.tlog"))
    frames = []
    while (message := log.recv_msg()) is not None:
        frames.append(bytes(message.get_msgbuf()))
    assert len(frames) == 2 and all(is_signed(frame) for frame in frames)


# -------------------------------------------------------------------------------- MAVSDK, signed
@pytest.mark.parametrize("same_key", [True, False])
def test_mavsdk_flies_a_signed_vehicle_through_the_relay_only_with_its_key(same_key: bool) -> None:
    """`--signing-key` end to end: a standalone sim-vehicle that signs (as `dronectl sim-vehicle
    --signing-key FILE` serves one), MAVSDK behind the signing relay (`flight.scenario.open_vehicle`)."""
    from drone_inspect_core.ports import free_port
    from flight.errors import VehicleConnectionError
    from flight.scenario import open_vehicle

    key = SigningKey.generate()
    port = free_port("udp")
    cfg = SimVehicleConfig(
        remote_port=port, local_port=0, video=False, signing_key=key,
        commander=CommanderConfig(arming_boot_delay_s=0.0),
    )  # fmt: skip
    with (
        World(WorldConfig(camera=CameraConfig(width=64, height=64)), seed=0) as world,
        SimVehicle(WorldVehicleModel(world), cfg) as vehicle,
    ):
        flown = open_vehicle(
            f"udpin://127.0.0.1:{port}", signing_key=key if same_key else SigningKey.generate()
        )
        with flown:
            if not same_key:  # its heartbeats never pass the relay, and nothing of ours reaches it
                with pytest.raises(VehicleConnectionError, match="NO_AUTOPILOT"):
                    flown.connect(3.0)
                assert vehicle.stats().messages_in == 0
                return
            flown.connect(10.0)
            flown.wait_ready(30.0)
            flown.arm(10.0)
            assert vehicle.snapshot().armed
        assert vehicle.stats().messages_unsigned == 0


def test_the_run_key_reaches_the_sim_vehicle_through_its_pipe_only() -> None:
    from drone_inspect_core.config_files import to_json
    from sim_world.vehicle.serve import SimVehicleRun, run_from_json, secret_json

    key = SigningKey.generate()
    run = SimVehicleRun(vehicle=SimVehicleConfig(signing_key=key, video=False))
    kept = to_json(run)  # the copy kept beside the report (what SimulatorProcess writes)
    assert key.hex() not in repr(kept) and "signing_key" not in repr(kept)
    assert run_from_json({**kept, **secret_json(run)}).vehicle.signing_key == key
    assert run_from_json(kept).vehicle.signing_key is None
