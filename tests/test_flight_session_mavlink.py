"""A flight session on a real-time MAVLink vehicle (the sim-vehicle subprocess, MAVSDK, its MJPEG stream):
Hold pressed in another thread while a centring runs reaches the vehicle at once (HOLD in its own
telemetry), the next instruction flies from there, and Kill stops the motors (forced disarm)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from controller.missions.results import InstructionResult
from controller.missions.schema import load_mission
from controller.missions.session import FlightSession, Phase
from controller.planning.loop_records import Outcome, StepRecord
from flight.types import FlightMode

MISSION = Path(__file__).resolve().parents[1] / "missions" / "regression" / "hil_three_instructions.yaml"


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_hold_from_another_thread_reaches_the_vehicle_then_the_next_instruction_and_kill(
    tmp_path: Path,
) -> None:
    mission = load_mission(MISSION)
    with FlightSession(mission, tmp_path / "session") as session:
        session.take_off()
        assert session.telemetry().flight_mode is FlightMode.OFFBOARD
        first_step = threading.Event()
        results: list[InstructionResult] = []

        def on_step(step: StepRecord) -> None:
            first_step.set()

        worker = threading.Thread(
            target=lambda: results.append(session.centre("the switch box", on_step=on_step))
        )
        worker.start()  # the far target: several moves from the start
        assert first_step.wait(60)
        pressed = time.monotonic()
        session.hold()  # the operator's thread: returns once the vehicle reports HOLD
        held_after_s = time.monotonic() - pressed
        worker.join(30)
        assert not worker.is_alive() and results[0].outcome is Outcome.STOPPED
        assert session.phase is Phase.HOLDING and session.telemetry().flight_mode is FlightMode.HOLD
        assert held_after_s < 3.0, held_after_s
        again = session.centre("the switch box")  # back into offboard, from where it held
        assert again.outcome is Outcome.CENTRED and again.passed, again.failures
        session.kill()
        assert session.phase is Phase.KILLED and not session.telemetry().armed
    result = session.result
    assert result is not None and [i["outcome"] for i in result.instructions] == ["stopped", "centred"]
