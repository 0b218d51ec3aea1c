"""Where a mission's wall time goes: its phases, from the runner's milestones and the loop's step timings.

A mission (`controller.missions.runner.run_mission`) passes through, in order:

- `start`: the kit is built (a simulator's process started and ready, MAVSDK and the camera opened, the
  models looked up);
- `connect`, `ready` (the autopilot's estimator), `takeoff` (arm, climb, place at the start, hover,
  offboard): `take_off_to_start`;
- `loop`: the centring loop, and within it `renders` (waiting for and reading a fresh frame, with the
  truth probe), `decisions` (detector and planner) and `moves` (flying and settling);
- `landing`: leave offboard, land, disarm;
- `report`: the final report written;
- `close`: the kit closed (a simulator's processes stopped).

Each phase is the wall time between two milestones (`flight.moves.Milestones`); a milestone a mission
never reached (it aborted) leaves its phase out and its time in the next phase reached.
"""

from __future__ import annotations

from collections.abc import Sequence

from controller.planning.loop_records import StepTiming

PHASES = ("start", "connect", "ready", "takeoff", "loop", "landing", "report", "close")
"""The phases of one mission, in order; together they are its whole wall time."""
LOOP_PARTS = ("renders", "decisions", "moves")
"""What the loop's time is spent on (the rest of it is the loop's own bookkeeping)."""

_MARKS = (
    ("connect", "connected_s"),
    ("ready", "ready_s"),
    ("takeoff", "offboard_s"),
    ("loop", "loop_end_s"),
    ("landing", "landed_s"),
)
"""Each flight phase and the milestone (`Milestones` key) that ends it."""


def flight_phases(wall_s: dict[str, float], timings: Sequence[StepTiming]) -> dict[str, float]:
    """The flight's phases (connect to landing) from the milestones' wall times (seconds from the flight's
    start) and the loop's parts from its steps' timings, in seconds."""
    phases: dict[str, float] = {}
    last_s = 0.0
    for phase, mark in _MARKS:
        if mark in wall_s:
            phases[phase] = wall_s[mark] - last_s
            last_s = wall_s[mark]
    phases["renders"] = sum(t.read_s for t in timings)
    phases["decisions"] = sum(t.detect_s + t.plan_s for t in timings)
    phases["moves"] = sum(t.move_s for t in timings)
    return {name: round(value, 4) for name, value in phases.items()}
