"""A lockstep paced by its client: the world runs only while the client waits on the vehicle's clock."""

from __future__ import annotations

import io
import threading
import time
from types import SimpleNamespace

from drone_inspect_core.launcher_requests import PACE_LINE
from flight.pacing import Pacer
from sim_world.process_entry import LauncherRequests
from sim_world.sitl.rig import LockstepPace, run_lockstep


def _requests(lines: bytes) -> LauncherRequests:
    requests = LauncherRequests(io.TextIOWrapper(io.BytesIO(lines)), "test")
    deadline = time.monotonic() + 2.0
    while requests.paces < lines.count(PACE_LINE) and time.monotonic() < deadline:
        time.sleep(0.01)
    return requests


def test_the_world_boots_flat_out_then_keeps_real_time_until_paced_then_a_lead_past_each_pace() -> None:
    unpaced = LockstepPace(_requests(b""), lead_s=0.1, silence_s=0.25, boot_s=10.0)
    assert not unpaced.holds(5.0) and not unpaced.holds(9.9)  # booting, no client yet: flat out
    assert not unpaced.holds(10.0)  # booted: real time from here
    assert unpaced.holds(10.5)  # half a simulated second ahead of the wall clock: wait
    requests = _requests(PACE_LINE)
    assert requests.paces == 1 and requests.take() is None  # a pace is counted, never queued
    pace = LockstepPace(requests, lead_s=0.1, silence_s=0.25)
    assert not pace.holds(2.0)  # the pace just came: 0.1 s more from here
    assert not pace.holds(2.09) and pace.holds(2.1)
    requests.paced_at -= 1.0  # the client has been silent a second of wall time: real time
    assert not pace.holds(2.1)
    assert pace.holds(2.3)
    assert not pace.holds(0.05)  # a new world, whose clock starts again: real time from there


def test_an_unpaced_loop_boots_flat_out_then_runs_at_the_wall_clocks_pace() -> None:
    world = SimpleNamespace(time_s=0.0)

    def tick() -> None:
        world.time_s += 0.004

    stop = threading.Event()
    pace = LockstepPace(_requests(b""), boot_s=1.0)
    loop = threading.Thread(
        target=run_lockstep, args=(lambda: world, tick, stop, None), kwargs={"pace": pace}
    )
    started = time.monotonic()
    loop.start()
    time.sleep(0.5)
    stop.set()
    loop.join(2.0)
    ran_s = time.monotonic() - started
    # one simulated second at once (thousands of ticks a second), then no more than the wall clock
    assert 1.0 + 0.1 <= world.time_s <= 1.0 + ran_s + 0.01, (world.time_s, ran_s)


def test_a_paced_loop_ticks_only_as_far_as_the_client_lets_it() -> None:
    requests = _requests(PACE_LINE)
    world = SimpleNamespace(time_s=0.0)

    def tick() -> None:
        world.time_s += 0.004

    stop = threading.Event()
    pace = LockstepPace(requests, lead_s=0.1, silence_s=5.0)
    loop = threading.Thread(
        target=run_lockstep, args=(lambda: world, tick, stop, None), kwargs={"pace": pace}
    )
    loop.start()
    time.sleep(0.3)
    held_at = world.time_s
    assert 0.1 <= held_at < 0.11  # one lead past the pace, then held
    requests.paced_at, requests.paces = time.monotonic(), requests.paces + 1  # the client waits again
    requests.paced.set()
    time.sleep(0.3)
    stop.set()
    loop.join(2.0)
    assert 0.2 <= world.time_s < 0.21  # another lead, from where it was held


def test_a_client_paces_every_period_of_the_vehicle_clock_and_while_a_command_blocks() -> None:
    paces: list[float] = []
    pacer = Pacer(lambda: paces.append(time.monotonic()), period_s=0.05, wall_period_s=0.02)
    for t in (1.0, 1.02, 1.04, 1.05, 1.09, 1.10):  # a wait polling the vehicle's clock
        pacer.tick(t)
    assert len(paces) == 3  # at 1.0, 1.05 and 1.10
    paces.clear()
    with pacer.blocked():  # a command awaiting its answer: the vehicle's clock may stand still
        time.sleep(0.2)
    stopped = len(paces)
    assert 4 <= stopped <= 12
    time.sleep(0.1)
    assert len(paces) == stopped  # no pacing once the command returned
    Pacer(None).tick(5.0)  # a real vehicle: nothing to pace
    with Pacer(None).blocked():
        pass
