"""A recording that fails (its folder removed mid-flight, a full disk) stops and says so; the flight goes on.

Writes into a removed folder do not fail (the open file lives on, unlinked): the relay checks each
second that its .tlog is still there, and the report writer's whole-file writes fail, said once.
"""

from __future__ import annotations

import json
import shutil
import socket
import threading
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as M

from flight.relay import MavlinkRelay


def _heartbeat() -> bytes:
    return M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, 0, 0, 3, 3).pack(
        M.MAVLink(None, 42, 1)
    )


def test_a_tlog_whose_folder_is_removed_stops_recording_and_the_relay_relays_on(tmp_path: Path) -> None:
    folder = tmp_path / "run"
    with (
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as vehicle,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as client,
    ):
        vehicle.bind(("127.0.0.1", 0))
        client.bind(("127.0.0.1", 0))
        client.settimeout(2.0)
        with MavlinkRelay(0, client.getsockname()[1], folder / "flight.tlog", vehicle_system_id=42) as relay:
            vehicle.sendto(_heartbeat(), relay.listen_address)
            assert client.recv(65535) == _heartbeat()
            shutil.rmtree(folder)
            deadline = time.monotonic() + 5.0
            while relay.recording_error is None and time.monotonic() < deadline:
                vehicle.sendto(_heartbeat(), relay.listen_address)
                assert client.recv(65535) == _heartbeat()  # relayed all along
                time.sleep(0.1)
            assert relay.recording_error is not None and "removed" in relay.recording_error
    assert not folder.exists()  # nothing written back into a folder somebody removed


def test_a_report_folder_removed_mid_flight_costs_the_report_not_the_flight(tmp_path: Path) -> None:
    from controller.missions.runner import run_mission
    from controller.missions.schema import Mission

    out = tmp_path / "report"
    removed = threading.Event()

    def remove_once_it_holds_a_step() -> None:
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline:
            report = json.loads((out / "report.json").read_text()) if (out / "report.json").is_file() else {}
            if any(entry["records"] for entry in report.get("instructions", [])):
                while out.exists():  # the writer may be adding a file meanwhile: until it is gone
                    shutil.rmtree(out, ignore_errors=True)
                removed.set()
                return
            time.sleep(0.005)

    remover = threading.Thread(target=remove_once_it_holds_a_step, daemon=True)
    remover.start()
    mission = Mission(name="removed-folder", planner="oracle", detector="truth", max_steps=6)
    result = run_mission(mission, out, media=True)
    remover.join(5.0)
    assert removed.is_set()
    assert result.outcome in ("centred", "step_budget"), result.error  # the flight went on to its end
    assert result.recording_errors and not result.report_written


def test_a_rerun_recording_that_does_not_fit_is_said_and_never_left_half_written(tmp_path: Path) -> None:
    pytest.importorskip("rerun", reason="the Rerun SDK is an optional extra")
    from small_fs import small_filesystem

    from controller.missions.runner import run_mission
    from controller.missions.schema import Mission

    mission = Mission(name="rerun-full-disk", planner="oracle", detector="truth", max_steps=6)
    with small_filesystem(tmp_path / "disk", 64) as disk:
        rrd = disk / "flight.rrd"
        result = run_mission(mission, tmp_path / "report", media=False, rerun_path=rrd)
        assert result.outcome == "centred" and result.report_written
        assert any("Rerun" in e for e in result.recording_errors), result.recording_errors
        assert list(disk.iterdir()) == []  # neither a truncated .rrd nor its temporary file
