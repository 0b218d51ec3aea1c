"""`dronectl bench fuzz`: hostile MAVLink against a flying mission's vehicle, relay and simulator bridge.

Missions are flown one after another (sim-mavlink or px4-sitl, the mission's planner, scenes drawn from
the seed) while an attacker on this machine sends, from its own sockets, `datagrams` random datagrams
and `messages` CRC-valid hostile messages (every message type with extreme values; and what would
take the vehicle over: forced arm and disarm, land, mode changes, 3 m/s setpoints, silenced
telemetry, a 0 speed limit; unsigned or signed with a wrong key, with a stranger's identity or a copy
of the controller's) to every port a run opens towards the vehicle:

- sim-mavlink: the sim-vehicle's UDP port, and the relay's two sides (where the vehicle sends, where
  MAVSDK sends);
- px4-sitl: the relay's two sides, and the bridge's simulator TCP port (connections that send junk).
  PX4's own MAVLink port is PX4's: v1.15 has no signing and obeys whatever reaches it (see
  docs/reliability.md); it is not attacked.

Counted per mission and in total: crashes (a vehicle, simulator, PX4 or relay that died before its
mission ended), commands obeyed from a sender other than the controller (what the sim-vehicle accepted
beyond what the relay forwarded from MAVSDK, or from another identity; a parameter changed that the
controller did not set), what each side dropped, and whether the mission was centred.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import random
import socket
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from controller.benchmarks.hostile_mavlink import (
    ATTACKER_SYSTEM_ID,
    hostile_commands,
    hostile_messages,
    random_datagrams,
    steering_messages,
)
from controller.missions.kits import open_kit
from controller.missions.kits.base import FlightKit
from controller.missions.report import claim_report_dir
from controller.missions.runner import fly_kit
from controller.missions.schema import Mission
from flight.relay import MavlinkRelay
from sim_world.vehicle.serve import SUMMARY_PREFIX

log = logging.getLogger(__name__)

CONTROLLER_IDENTITY = (245, 190)
"""MAVSDK's MAVLink identity as a ground station: a copy of it is one of the attacker's disguises."""
CONTROLLER_PARAMS = {"MIS_TAKEOFF_ALT"}
"""What the controller itself sets on a vehicle (its takeoff altitude)."""


@dataclass(frozen=True)
class FuzzConfig:
    vehicle: str = "sim-mavlink"
    datagrams: int = 100_000
    messages: int = 10_000
    rate_per_s: float = 2500.0
    """Hostile datagrams per second while a mission flies (spread over the targets)."""
    seed: int = 0
    max_missions: int = 20
    px4_dir: str | None = None

    def __post_init__(self) -> None:
        if self.vehicle not in ("sim-mavlink", "px4-sitl"):
            raise ValueError(f"vehicle must be sim-mavlink or px4-sitl, got {self.vehicle!r}")
        if self.datagrams < 0 or self.messages < 0 or self.datagrams + self.messages == 0:
            raise ValueError("datagrams and messages must be >= 0, and not both 0")
        if not self.rate_per_s > 0 or self.max_missions < 1:
            raise ValueError("rate_per_s must be > 0 and max_missions >= 1")


@dataclass
class MissionFuzz:
    """One mission under attack."""

    name: str
    outcome: str
    sent: int
    crashed: list[str] = field(default_factory=list)
    obeyed_from_strangers: int = 0
    foreign_params_changed: dict[str, float] = field(default_factory=dict)
    relay: dict[str, int] = field(default_factory=dict)
    vehicle_link: dict[str, Any] | None = None
    bridge_connections_refused: int = 0
    error: str | None = None


class Attacker:
    """Sends the hostile stream to the current targets at a steady rate from a background thread."""

    def __init__(self, stream: list[bytes], rate_per_s: float) -> None:
        self.stream, self.rate_per_s = stream, rate_per_s
        self.sent = 0
        self.tcp_refused = 0
        self._udp: list[tuple[str, int]] = []
        self._tcp: list[tuple[str, int]] = []
        self._armed = threading.Event()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self._thread = threading.Thread(target=self._run, name="fuzz-attacker", daemon=True)
        self._thread.start()

    @property
    def done(self) -> bool:
        return self.sent >= len(self.stream)

    def attack(self, udp: list[tuple[str, int]], tcp: list[tuple[str, int]]) -> None:
        with self._lock:
            self._udp, self._tcp = list(udp), list(tcp)
        self._armed.set()

    def hold(self) -> None:
        self._armed.clear()

    def close(self) -> None:
        self._stop.set()
        self._armed.set()
        self._thread.join(5.0)
        self._sock.close()

    def _run(self) -> None:
        batch = 50
        while not self._stop.is_set() and not self.done:
            if not self._armed.wait(0.1):
                continue
            with self._lock:
                udp, tcp = self._udp, self._tcp
            started = time.monotonic()
            for i in range(batch):
                if self.done:
                    break
                data = self.stream[self.sent]
                target = udp[(self.sent + i) % len(udp)] if udp else None
                if target is not None:
                    with contextlib.suppress(
                        OSError
                    ):  # a port that just closed: the next mission's come soon
                        self._sock.sendto(data, target)
                self.sent += 1
            if tcp and self.sent % 1000 < batch:  # now and then, a connection to the simulator port
                self._dial(tcp[0], self.stream[self.sent - 1])
            time.sleep(max(0.0, batch / self.rate_per_s - (time.monotonic() - started)))

    def _dial(self, address: tuple[str, int], junk: bytes) -> None:
        try:
            with socket.create_connection(address, timeout=0.5) as conn:
                conn.sendall(junk)
        except OSError:
            self.tcp_refused += 1  # refused: the bridge stopped listening once PX4 was in


def hostile_stream(config: FuzzConfig) -> list[bytes]:
    """The whole attack, shuffled: random datagrams and hostile valid messages in the asked numbers."""
    rng = random.Random(config.seed)
    wrong_key = rng.randbytes(32)
    quarter = config.messages // 4
    valid = (
        hostile_messages(rng, config.messages - 3 * quarter, (0, 1))
        + hostile_commands(rng, quarter, (0,))
        + steering_messages(rng, quarter, (0,), CONTROLLER_IDENTITY)
        + steering_messages(rng, quarter, (0,), (ATTACKER_SYSTEM_ID, 190), wrong_key=wrong_key)
    )
    stream = random_datagrams(rng, config.datagrams) + valid
    rng.shuffle(stream)
    return stream


def _targets(kit: FlightKit) -> tuple[list[tuple[str, int]], list[tuple[str, int]]]:
    relay = kit.tlog
    ports = kit.info.get("ports", {})
    udp: list[tuple[str, int]] = []
    if isinstance(relay, MavlinkRelay):
        udp += [("127.0.0.1", relay.listen_address[1]), relay.client_side_address]
    if ports.get("sim_udp"):
        udp.append(("127.0.0.1", int(ports["sim_udp"])))
    tcp = [("127.0.0.1", int(ports["px4_simulator_tcp"]))] if ports.get("px4_simulator_tcp") else []
    return udp, tcp


def _alive(pid: int | None) -> bool:
    if pid is None:
        return True
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def _vehicle_link(out_dir: Path) -> dict[str, Any] | None:
    """The sim-vehicle's last line: what its link accepted and dropped (`sim_world.vehicle.serve`)."""
    try:
        lines = (out_dir / "sim_vehicle.log").read_text(errors="replace").splitlines()
    except OSError:
        return None
    for line in reversed(lines):
        if line.startswith(SUMMARY_PREFIX):
            return json.loads(line[len(SUMMARY_PREFIX) :])
    return None


def fly_under_attack(mission: Mission, out_dir: Path, attacker: Attacker) -> MissionFuzz:
    """One mission with the attacker on every port it opens; what got through and what died."""
    out = claim_report_dir(out_dir)
    before = attacker.sent
    crashed: list[str] = []
    relay_stats: dict[str, int] = {}
    outcome, error, refused_before = "error", None, attacker.tcp_refused
    try:
        with open_kit(mission, out) as kit:
            attacker.attack(*_targets(kit))
            try:
                result = fly_kit(kit, mission, out, media=False)
            finally:
                attacker.hold()
            outcome, error = result.outcome, result.error
            for what in ("simulator_pid", "px4_pid"):
                if what in kit.info and not _alive(kit.info[what]):
                    crashed.append(what.removesuffix("_pid"))
            relay = kit.tlog
            if isinstance(relay, MavlinkRelay):
                if not relay._thread.is_alive():
                    crashed.append("relay")
                relay_stats = {
                    "forwarded_to_vehicle": sum(relay.uplink_counts.values()),
                    "dropped_foreign": relay.foreign_datagrams,
                    "dropped_unsigned": relay.unsigned_dropped,
                }
    except Exception as exc:
        error = f"{type(exc).__name__}: {exc}"
    fuzz = MissionFuzz(mission.name, outcome, attacker.sent - before, crashed, relay=relay_stats, error=error)
    fuzz.bridge_connections_refused = attacker.tcp_refused - refused_before
    link = fuzz.vehicle_link = _vehicle_link(out)
    if link is not None:
        from_controller = link["accepted_from"].get("/".join(map(str, CONTROLLER_IDENTITY)), 0)
        strangers = link["accepted"] - from_controller
        beyond_relay = max(0, from_controller - relay_stats.get("forwarded_to_vehicle", from_controller))
        fuzz.obeyed_from_strangers = strangers + beyond_relay
        fuzz.foreign_params_changed = {
            k: v for k, v in link["params_changed"].items() if k not in CONTROLLER_PARAMS
        }
    return fuzz


def run_fuzz(config: FuzzConfig, out_dir: Path, base: Mission) -> dict[str, Any]:
    """Missions under attack until the whole hostile stream is sent (or `max_missions`); the numbers."""
    stream = hostile_stream(config)
    attacker = Attacker(stream, config.rate_per_s)
    missions: list[MissionFuzz] = []
    started = time.monotonic()
    load_before = os.getloadavg()[0]
    try:
        for i in range(config.max_missions):
            if attacker.done:
                break
            mission = base.with_seed(config.seed * 1000 + i).model_copy(update={"name": f"fuzz-{i:02d}"})
            fuzz = fly_under_attack(mission, out_dir / mission.name, attacker)
            log.info("%s: %s, %d hostile datagrams sent", mission.name, fuzz.outcome, fuzz.sent)
            missions.append(fuzz)
    finally:
        attacker.close()
    return {
        "config": asdict(config),
        "hostile_sent": attacker.sent,
        "hostile_planned": len(stream),
        "missions": [asdict(m) for m in missions],
        "crashes": sum(len(m.crashed) for m in missions),
        "obeyed_from_strangers": sum(m.obeyed_from_strangers for m in missions),
        "foreign_params_changed": sum(len(m.foreign_params_changed) for m in missions),
        "centred": sum(m.outcome == "centred" for m in missions),
        "flown": len(missions),
        "wall_s": round(time.monotonic() - started, 1),
        "load_average_before": load_before,
        "cpus": os.cpu_count(),
    }
