"""Connection URLs are checked with a fix in the message; link loss is detected by the monitor."""

from __future__ import annotations

import pytest

from flight.errors import ConnectionUrlError, LinkLostError
from flight.link import LinkMonitor
from flight.urls import validate_connection_url


@pytest.mark.parametrize(
    "url",
    [
        "udpin://0.0.0.0:14540",
        "udpin://127.0.0.1:14741",
        "udpout://192.168.1.10:14550",
        "tcpout://10.0.0.2:5760",
        "serial:///dev/ttyACM0:57600",
        "serial://COM3:115200",
        "udp://:14540",
    ],
)
def test_urls_mavsdk_accepts_pass(url: str) -> None:
    assert validate_connection_url(url) == url


@pytest.mark.parametrize(
    ("url", "fix"),
    [
        ("udpin://localhost:14540", "udpin://127.0.0.1:14540"),
        ("udpin://:14540", "udpin://0.0.0.0:14540"),
        ("udpin://0.0.0.0:99999", "1 to 65535"),
        ("udpin://drone.local:14540", "numeric IP"),
        ("http://127.0.0.1:14540", "unknown scheme"),
        ("127.0.0.1:14540", "scheme://address"),
        ("serial:///dev/ttyACM0:57601", "57600"),
        ("serial:///dev/ttyACM0", "baud rate"),
    ],
)
def test_bad_urls_get_an_error_naming_the_url_and_the_fix(url: str, fix: str) -> None:
    with pytest.raises(ConnectionUrlError) as info:
        validate_connection_url(url)
    assert repr(url) in str(info.value)
    assert fix in str(info.value)
    assert info.value.origin == "connect()"


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s


def test_silence_longer_than_the_timeout_is_link_loss() -> None:
    clock = FakeClock()
    link = LinkMonitor(2.0, clock)
    clock.now_s += 1.9
    link.check("telemetry()")
    link.heard()
    clock.now_s += 1.9
    link.check("telemetry()")
    clock.now_s += 0.2
    with pytest.raises(LinkLostError, match=r"telemetry\(\): LINK_LOST") as info:
        link.check("telemetry()")
    assert info.value.silent_s == pytest.approx(2.1)


def test_mavsdk_disconnect_is_link_loss_once_telemetry_is_quiet_too() -> None:
    clock = FakeClock()
    link = LinkMonitor(2.0, clock)
    link.set_connected(False)  # three heartbeats lost in a row...
    link.check("arm()")  # ...while attitude still arrives: a lossy link, alive
    clock.now_s += 0.6  # and now nothing at all for 0.6 s: gone
    with pytest.raises(LinkLostError):
        link.check("arm()")
    link.heard()
    link.check("arm()")


def test_a_lockstep_vehicle_is_lost_only_by_its_silence() -> None:
    clock = FakeClock()
    link = LinkMonitor(2.0, clock, connection_state=False)
    link.set_connected(False)  # MAVSDK's wall-clock heartbeat timeout: a slow simulator, not a lost one
    clock.now_s += 1.5  # telemetry in sparse bursts
    link.check("sleep()")
    clock.now_s += 0.6  # 2.1 s of silence: gone
    with pytest.raises(LinkLostError):
        link.check("sleep()")


def test_a_simulator_whose_process_exited_is_lost_at_once_not_after_the_timeout() -> None:
    clock = FakeClock()
    alive = [True]
    link = LinkMonitor(6.0, clock, connection_state=False, peer_alive=lambda: alive[0])
    clock.now_s += 0.2
    link.check("sleep()")  # running and recently heard: fine
    alive[0] = False  # PX4 killed: its bridge ends
    with pytest.raises(LinkLostError, match="process has exited"):
        link.check("sleep()")


def test_a_command_timeout_on_a_silent_vehicle_is_a_lost_link_and_on_a_live_one_returns_at_once() -> None:
    now = [0.0]

    def clock() -> float:
        now[0] += 0.05  # every look at the clock is 50 ms later
        return now[0]

    silent = LinkMonitor(timeout_s=1.0, clock=clock)
    now[0] += 0.6  # quiet for 0.6 s when the command times out
    with pytest.raises(LinkLostError):
        silent.raise_if_lost("start_offboard()", poll_s=0.0)
    live = LinkMonitor(timeout_s=1.0, clock=clock)
    live.heard()
    live.raise_if_lost("start_offboard()", poll_s=0.0)  # heard just now: no verdict to wait for


def test_a_command_that_times_out_on_a_silent_vehicle_raises_link_lost_not_a_refusal() -> None:
    from mavsdk.plugins.action import ActionError, ActionResult

    from flight.mavsdk.link import resend_on_timeout

    def land() -> None:
        raise ActionError(ActionResult.TIMEOUT, "land()")

    now = [0.0]

    def clock() -> float:
        now[0] += 0.05
        return now[0]

    silent = LinkMonitor(timeout_s=1.0, clock=clock)
    now[0] += 0.6  # the vehicle died: quiet since
    with pytest.raises(LinkLostError, match=r"land\(\)"):
        resend_on_timeout(land, silent, attempts=2)
    live = LinkMonitor(timeout_s=1.0, clock=clock)
    live.heard()  # a vehicle still talking that does not ack: the TIMEOUT itself, as before
    with pytest.raises(ActionError):
        resend_on_timeout(land, live, attempts=2)
    with pytest.raises(ActionError):  # no link given: as before
        resend_on_timeout(land, attempts=2)


def test_a_command_to_a_simulator_whose_process_exited_is_not_sent_again() -> None:
    """Each copy waits out MAVSDK's own resends (about 2 s): three copies to a PX4 killed during an
    offboard stop() ended a mission 6.8 s after the kill instead of at once."""
    from mavsdk.plugins.offboard import OffboardError, OffboardResult

    from flight.mavsdk.link import resend_on_timeout

    calls = []

    def stop() -> None:
        calls.append("stop()")
        raise OffboardError(OffboardResult.TIMEOUT, "stop()")

    alive = [True]
    link = LinkMonitor(timeout_s=6.0, peer_alive=lambda: alive[0])
    link.heard()
    alive[0] = False  # the simulator's process exited
    with pytest.raises(LinkLostError, match=r"stop\(\).*process has exited"):
        resend_on_timeout(stop, link, attempts=3)
    assert calls == ["stop()"]
    alive[0] = True  # alive and talking, only the acks lost: every copy is sent, as before
    calls.clear()
    with pytest.raises(OffboardError):
        resend_on_timeout(stop, link, attempts=3)
    assert calls == ["stop()"] * 3
