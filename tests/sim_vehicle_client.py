"""A small pymavlink ground station for tests of the simulated vehicle, over real UDP.

It binds the port the vehicle sends to (as MAVSDK's `udpin://` does), records every
message with its arrival time on a reader thread, and offers waits with timeouts.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from drone_inspect_core.signing import SigningKey, enable_signing
from sim_world.rendering.camera import CameraConfig
from sim_world.vehicle.commander import CommanderConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.server import SimVehicle
from sim_world.vehicle.world_model import WorldVehicleModel
from sim_world.world import World, WorldConfig

Msg = mavlink.MAVLink_message
WAIT_SLACK = 4.0


@dataclass(frozen=True)
class Received:
    t: float  # time.monotonic() at arrival
    msg: Msg


class MavlinkTestClient:
    """Listens on `listen_port`; sends to the vehicle once it has heard from it."""

    def __init__(self, listen_port: int, sysid: int = 245, compid: int = 190):
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        # Faster than real time the vehicle streams ~500 messages a wall second: the default 208 KiB
        # buffer holds well under a second of them, and a reader thread starved that long on a loaded
        # machine lost a COMMAND_ACK in the queue's overflow (as MAVSDK's own buffer is large).
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self._sock.bind(("127.0.0.1", listen_port))  # 0: a free port, see `port`
        self.port: int = self._sock.getsockname()[1]
        self._sock.settimeout(0.05)
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self._lock = threading.Lock()
        self.received: list[Received] = []
        self.vehicle: tuple[str, int] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self._sock.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            now = time.monotonic()
            msgs = [
                m
                for m in self._parser.parse_buffer(data) or []
                if not isinstance(m, mavlink.MAVLink_bad_data)
            ]
            with self._lock:
                self.vehicle = addr
                self.received.extend(Received(now, m) for m in msgs)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self._sock.close()

    def __enter__(self) -> MavlinkTestClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----------------------------------------------------------------- reading
    def since(self, t: float, kind: str | None = None) -> list[Received]:
        with self._lock:
            return [r for r in self.received if r.t >= t and (kind is None or r.msg.get_type() == kind)]

    def wait_for(
        self,
        kind: str,
        timeout_s: float,
        where: Callable[[Msg], bool] = lambda m: True,
        after: float | None = None,
    ) -> Msg:
        """The first `kind` message (arrived after `after`, default now) that satisfies `where`.

        The wait is `timeout_s` × `WAIT_SLACK`: a test's timeout says when the vehicle should have
        answered on an idle machine; on a loaded one (CI, other jobs) only a failure waits longer.
        """
        start = time.monotonic() if after is None else after
        deadline = time.monotonic() + timeout_s * WAIT_SLACK
        while time.monotonic() < deadline:
            for r in self.since(start, kind):
                if where(r.msg):
                    return r.msg
            time.sleep(0.01)
        raise TimeoutError(f"no {kind} matching the condition within {timeout_s} s")

    def wait_vehicle(self, timeout_s: float = 5.0) -> Msg:
        hb = self.wait_for("HEARTBEAT", timeout_s, after=0.0)
        assert self.vehicle is not None
        return hb

    def heartbeat_after(self, t: float, timeout_s: float = 3.0) -> Msg:
        return self.wait_for("HEARTBEAT", timeout_s, after=t)

    # ----------------------------------------------------------------- sending
    def sign_with(self, key: SigningKey | None) -> None:
        """Sign everything sent from now on with `key` (None: send unsigned again)."""
        if key is None:
            self._mav.signing.sign_outgoing = False
        else:
            enable_signing(self._mav, key)

    def send(self, msg: Msg) -> None:
        if self.vehicle is None:
            raise RuntimeError("no heartbeat from the vehicle yet")
        self._sock.sendto(msg.pack(self._mav), self.vehicle)
        self._mav.seq = (self._mav.seq + 1) % 256

    def command(self, command: int, *params: float, timeout_s: float = 2.0, target: int = 1) -> list[int]:
        """Send COMMAND_LONG; return the results of the acks that arrive within 0.2 s of the first.

        As the MAVLink command protocol (and MAVSDK) does, a command not acked within `timeout_s` is
        sent once more with `confirmation` 1; the ack must then come within the rest of the wait. The
        vehicle answers each copy, so after a resend each result is counted once (a loaded machine can
        ack the first copy late, beside the second's ack)."""
        p = [*params, *[0.0] * (7 - len(params))]
        t0 = time.monotonic()
        self.send(mavlink.MAVLink_command_long_message(target, 1, command, 0, *p))

        def acked(m: Msg) -> bool:
            return m.command == command

        resent = False
        try:
            self.wait_for("COMMAND_ACK", timeout_s / WAIT_SLACK, acked, after=t0)
        except TimeoutError:
            self.send(mavlink.MAVLink_command_long_message(target, 1, command, 1, *p))
            resent = True
            self.wait_for("COMMAND_ACK", timeout_s * (WAIT_SLACK - 1) / WAIT_SLACK, acked, after=t0)
        time.sleep(0.2)
        results = [r.msg.result for r in self.since(t0, "COMMAND_ACK") if r.msg.command == command]
        return list(dict.fromkeys(results)) if resent else results

    def setpoint(self, frame: int, vx: float, vy: float, vz: float, yaw_rate: float = 0.0) -> None:
        self.send(
            mavlink.MAVLink_set_position_target_local_ned_message(
                0, 1, 1, frame, 1479, 0, 0, 0, vx, vy, vz, 0, 0, 0, 0, yaw_rate
            )
        )

    def wait_text(self, fragment: str, timeout_s: float, after: float = 0.0) -> str:
        """The first STATUSTEXT since `after` containing `fragment` (texts can trail the ack they explain)."""
        return self.wait_for("STATUSTEXT", timeout_s, lambda m: fragment in m.text, after=after).text

    def texts(self, after: float = 0.0) -> list[str]:
        return [r.msg.text for r in self.since(after, "STATUSTEXT")]

    def rate_hz(self, kind: str, seconds: float) -> float:
        """Count `kind` messages over the next `seconds`."""
        t0 = time.monotonic()
        time.sleep(seconds)
        return len([r for r in self.since(t0, kind) if r.t <= t0 + seconds]) / seconds


@contextlib.contextmanager
def served_vehicle(**config: object) -> Iterator[tuple[MavlinkTestClient, SimVehicle]]:
    """A sim-vehicle (the real PyBullet world, 64 px, no video) streaming to a test client, its
    controller, both on free ports; `config`: more `SimVehicleConfig` fields."""
    with (
        World(WorldConfig(camera=CameraConfig(width=64, height=64)), seed=0) as world,
        MavlinkTestClient(0) as client,
    ):
        cfg = SimVehicleConfig(
            remote_port=client.port,
            local_port=0,
            video=False,
            commander=CommanderConfig(arming_boot_delay_s=0.0),
            **config,  # type: ignore[arg-type]
        )
        with SimVehicle(WorldVehicleModel(world), cfg) as vehicle:
            client.wait_vehicle()
            yield client, vehicle
