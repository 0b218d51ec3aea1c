"""A flight session on a real-time MAVLink vehicle (the sim-vehicle subprocess, MAVSDK, its MJPEG stream,
`missions/regression/hil_three_instructions.yaml`): Hold pressed in another thread while a centring runs
reaches the vehicle at once (HOLD in its own telemetry); the next instructions fly from there, each
centred on its own target per the sim's truth; Kill stops the motors (forced disarm); the vehicle's own
record (the .tlog) shows one take-off."""

from __future__ import annotations

import itertools
import threading
import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from controller.missions.results import InstructionResult
from controller.missions.schema import load_mission
from controller.missions.session import FlightSession, Phase
from controller.planning.loop_records import Outcome, StepRecord
from flight.types import FlightMode

MISSION = Path(__file__).resolve().parents[1] / "missions" / "regression" / "hil_three_instructions.yaml"


def landed_states(tlog: Path) -> list[int]:
    """The vehicle's own landed state (EXTENDED_SYS_STATE) through the flight, each change once."""
    log = mavutil.mavlink_connection(str(tlog))
    states: list[int] = []
    while (message := log.recv_match(type="EXTENDED_SYS_STATE")) is not None:
        if not states or states[-1] != message.landed_state:
            states.append(message.landed_state)
    return states


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_hold_from_another_thread_then_two_instructions_then_kill_in_one_take_off(tmp_path: Path) -> None:
    out = tmp_path / "session"
    with FlightSession(load_mission(MISSION), out) as session:
        session.take_off()
        assert session.telemetry().flight_mode is FlightMode.OFFBOARD
        first_step = threading.Event()
        results: list[InstructionResult] = []

        def on_step(step: StepRecord) -> None:
            first_step.set()

        worker = threading.Thread(
            target=lambda: results.append(session.centre("the switch box", on_step=on_step))
        )
        worker.start()  # the farthest target from the start: several moves
        assert first_step.wait(60)
        pressed = time.monotonic()
        session.hold()  # the operator's thread: returns once the vehicle reports HOLD
        held_after_s = time.monotonic() - pressed
        worker.join(30)
        assert not worker.is_alive() and results[0].outcome is Outcome.STOPPED
        assert session.phase is Phase.HOLDING and session.telemetry().flight_mode is FlightMode.HOLD
        assert held_after_s < 3.0, held_after_s
        for words, kind in (("the switch box", "switchbox"), ("the red valve", "valve")):
            result = session.centre(words)  # back into offboard, from where it held
            assert result.passed, result.failures
            assert result.target["kind"] == kind and not result.wrong_target
        session.kill()
        assert session.phase is Phase.KILLED and not session.telemetry().armed
    assert session.result is not None
    assert [i["outcome"] for i in session.result.instructions] == ["stopped", "centred", "centred"]
    states = landed_states(out / "flight.tlog")
    on_ground = mavlink.MAV_LANDED_STATE_ON_GROUND
    assert states[0] == on_ground
    assert (
        sum(1 for a, b in itertools.pairwise(states) if a == on_ground and b != on_ground) == 1
    )  # one take-off
