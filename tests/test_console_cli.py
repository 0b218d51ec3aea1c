"""`dronectl console` as a user runs it: bad options in one line (exit 2), and a served console that
prints its address with a token, refuses a request without it, and stops on SIGTERM (exit 143, the
report written, nothing left running)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _dronectl(*args: str) -> list[str]:
    return [sys.executable, "-m", "dronectl.cli", *args]


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--host", "not an address"], "is not an IP address"),
        (["--fps", "0"], "argument --fps"),
        (["--port", "70000"], "argument --port"),
        (["--mission", "no/such/mission.yaml"], "no/such/mission.yaml"),
    ],
)
def test_bad_options_are_one_line(tmp_path: Path, args: list[str], said: str) -> None:
    done = subprocess.run(
        _dronectl("console", "--out", str(tmp_path / "out"), *args),
        capture_output=True, text=True, timeout=120, cwd=REPO,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dronectl console: ") and said in lines[0]


def _children(pid: int) -> list[int]:
    found = []
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            text = status.read_text()
        except OSError:
            continue
        match = re.search(r"^PPid:\s+(\d+)$", text, re.M)
        if match and int(match.group(1)) == pid:
            found.append(int(status.parent.name))
    return found


@pytest.mark.timeout(180)
def test_a_served_console_needs_its_token_and_stops_on_sigterm(tmp_path: Path) -> None:
    out = tmp_path / "session"
    process = subprocess.Popen(
        _dronectl("console", "--out", str(out)),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    try:
        url = None
        deadline = time.monotonic() + 120
        assert process.stdout is not None
        while url is None and time.monotonic() < deadline:
            line = process.stdout.readline()
            if not line:
                break
            match = re.match(r"console: (http://127\.0\.0\.1:\d+/c/[\w-]+/)$", line.strip())
            url = match.group(1) if match else None
        assert url is not None, process.stderr.read() if process.stderr else ""
        with urllib.request.urlopen(url, timeout=10) as response:
            assert response.status == 200
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(re.sub(r"/c/[\w-]+/", "/c/wrong/", url), timeout=10)
        assert refused.value.code == 403
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=60) == 128 + signal.SIGTERM
    finally:
        if process.poll() is None:
            process.kill()
    assert (out / "report.json").is_file()
    assert _children(process.pid) == []
