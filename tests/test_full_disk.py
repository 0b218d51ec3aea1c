"""Recording never costs control: a full or read-only disk stops the recording, never the flight.

The disks are real: small tmpfs filesystems (`small_fs`), filled by the flight itself (mostly its
.tlog) or mounted read-only. The flight is a real sim-mavlink mission through the CLI.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M
from small_fs import fill, small_filesystem

from controller.missions.report import ReportWriter
from drone_inspect_core.files import CLAIM_MARKER, OutputDirError, claim_dir
from flight.relay import INCOMPLETE_SUFFIX, MavlinkRelay

REPO = Path(__file__).resolve().parents[1]


def test_a_full_disk_stops_the_tlog_and_never_the_relay(tmp_path: Path) -> None:
    with small_filesystem(tmp_path / "disk", 16) as disk:
        vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        client.bind(("127.0.0.1", 0))
        client.settimeout(1.0)
        mav = M.MAVLink(None, srcSystem=3, srcComponent=1)
        with vehicle, client, MavlinkRelay(0, client.getsockname()[1], disk / "flight.tlog") as relay:
            for i in range(1500):  # ~70 kB of log through a 16 kB disk
                beat = M.MAVLink_heartbeat_message(2, 12, 0, i, 4, 3).pack(mav)
                vehicle.sendto(beat, relay.listen_address)
                assert client.recv(65535) == beat, f"datagram {i} was not relayed"
            assert relay.recording_error is not None and "No space left" in relay.recording_error
            logged = relay.messages_logged
        incomplete = disk / ("flight" + INCOMPLETE_SUFFIX)
        assert not (disk / "flight.tlog").exists() and incomplete.exists()
        log = mavutil.mavlink_connection(str(incomplete))
        count = 0
        while (message := log.recv_match()) is not None:
            assert message.get_type() == "HEARTBEAT"
            count += 1
        assert count == logged > 100  # every message it kept is whole; nothing half-written


def test_the_report_writer_keeps_the_outcome_on_a_full_disk(tmp_path: Path) -> None:
    with small_filesystem(tmp_path / "disk", 64) as disk:
        out = claim_dir(disk / "report", "report folder")
        writer = ReportWriter(out, {"mission": "m", "padding": "x" * 2000}, 10.0, media=False)
        fill(disk)
        final = writer.finish({"outcome": "centred", "passed": True})
        assert final["report_written"]
        report = json.loads((out / "report.json").read_text())
        assert (report["status"], report["outcome"]) == ("finished", "centred")
        assert sorted(p.name for p in out.iterdir()) == ["report.json"]  # no .tmp, no reserve, no claim


def test_a_read_only_or_taken_out_folder_is_one_line_before_anything_starts(tmp_path: Path) -> None:
    with small_filesystem(tmp_path / "ro", 16, read_only=True) as ro:
        done = subprocess.run(
            [sys.executable, "-m", "dronectl", "fly", "--out", str(ro / "report")],
            cwd=REPO, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert done.returncode == 2
        assert "Traceback" not in done.stderr
        lines = [line for line in done.stderr.splitlines() if line.startswith("dronectl fly:")]
        assert len(lines) == 1 and "Read-only file system" in lines[0], done.stderr
    taken = tmp_path / "taken"
    claim_dir(taken)
    try:
        claim_dir(taken)
    except OutputDirError as exc:
        assert f"pid {os.getpid()}" in str(exc)
    else:
        raise AssertionError("a folder claimed by a run was claimed again")


_CLAIM = """
import sys, time
from drone_inspect_core.files import OutputDirError, claim_dir
time.sleep(max(0.0, float(sys.argv[2]) - time.time()))
try:
    claim_dir(sys.argv[1])
    print("won")
except OutputDirError:
    print("lost")
"""


def test_two_runs_never_share_a_folder(tmp_path: Path) -> None:
    for trial in range(8):
        folder = tmp_path / f"out{trial}"
        if trial % 2:
            folder.mkdir()  # an existing empty folder, as well as a new one
        at = f"{time.time() + 0.5}"
        runs = [
            subprocess.Popen(
                [sys.executable, "-c", _CLAIM, str(folder), at], cwd=REPO, stdout=subprocess.PIPE, text=True
            )
            for _ in range(3)
        ]
        said = sorted(run.communicate(timeout=30)[0].strip() for run in runs)
        assert said == ["lost", "lost", "won"], said
        assert [p.name for p in folder.iterdir()] == [CLAIM_MARKER]


def test_a_sim_mavlink_flight_that_fills_its_disk_lands_and_reports(tmp_path: Path) -> None:
    with small_filesystem(tmp_path / "disk", 96) as disk:
        done = subprocess.run(
            [
                sys.executable, "-m", "dronectl", "fly", "--vehicle", "sim-mavlink",
                "--sim-speed", "max", "--out", str(disk / "report"),
            ],
            cwd=REPO, capture_output=True, text=True, timeout=240,
        )  # fmt: skip
        out = done.stdout + done.stderr
        assert "Traceback" not in out, out[-3000:]
        assert done.returncode == 0, out[-3000:]  # PASS: centred, landed and disarmed over the link
        assert "PASS" in done.stdout and "centred" in done.stdout
        assert "not recorded: flight.tlog" in done.stdout  # said, once
        folder = disk / "report"
        names = sorted(p.name for p in folder.iterdir())
        assert not [n for n in names if n.endswith(".tmp") or n in (".reserve", CLAIM_MARKER)], names
        assert "flight.tlog" not in names and "flight" + INCOMPLETE_SUFFIX in names
        report = json.loads((folder / "report.json").read_text())
        assert (report["status"], report["outcome"], report["passed"]) == ("finished", "centred", True)
        assert any("flight.tlog" in e for e in report["recording_errors"])
