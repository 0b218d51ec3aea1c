"""Fly one mission: build its vehicle, camera, detector and planner, fly its instructions, write the report.

`run_mission(mission, out_dir)` opens a `FlightKit` for the mission's vehicle
(`controller.missions.kits.open_kit`):

- `vehicle: sim`: the in-process PyBullet world (`flight.pybullet_backend`) and
  its rendered camera; truth from the world. Faster than real time.
- `vehicle: sim-mavlink`: `dronectl sim-vehicle` as a subprocess (the same world
  served as a PX4-flavoured MAVLink vehicle and an MJPEG stream), flown with the
  MAVSDK backend and the stream camera exactly as a real drone; truth from the
  sim's `/truth.json` endpoint, for judging only (`controller.missions.kits.sim_mavlink`).
- `vehicle: px4-sitl` / `ardupilot-sitl`: real autopilot firmware (SITL) flying that world in
  lockstep through a bridge (`kits.px4_sitl`, `kits.ardupilot_sitl`), flown as a real vehicle.
- a MAVLink URL: a real vehicle (PX4 or ArduPilot) and the `camera` stream URL; no truth.

`fly_kit(kit, mission, out_dir)` then flies it as a flight session
(`controller.missions.session.FlightSession.fly`): connect → ready → arm → take off →
(sim: place the drone at the mission's start pose) → zero setpoint → offboard → the centring
loop for each instruction, holding in between → leave offboard → land → disarm. An error or
Ctrl-C in any of it holds and lands, and the report (written after every step) keeps every
step recorded before it.
"""

from __future__ import annotations

from pathlib import Path

from controller.missions.kits.base import FlightKit, LoadedModels
from controller.missions.report import REPORT_JSON, claim_report_dir, hold_reserve, write_setup_failure
from controller.missions.results import MissionResult
from controller.missions.schema import Mission
from controller.missions.session import FlightSession
from drone_inspect_core.signing import SigningKey
from flight.safety import SafetyLimits


def fly_kit(
    kit: FlightKit,
    mission: Mission,
    out_dir: str | Path,
    limits: SafetyLimits | None = None,
    media: bool = True,
    rerun_path: Path | None = None,
) -> MissionResult:
    """Fly the mission's instructions with `kit` (left open) and write the report folder; never loses a
    recorded step. `rerun_path`: also record the flight to this new .rrd file."""
    with FlightSession(
        mission, out_dir, kit=kit, limits=limits, media=media, rerun_path=rerun_path
    ) as session:
        session.fly()
    assert session.result is not None
    return session.result


def run_mission(
    mission: Mission,
    out_dir: str | Path,
    limits: SafetyLimits | None = None,
    media: bool = True,
    models: LoadedModels | None = None,
    rerun_path: str | Path | None = None,
    claimed: bool = False,
    signing_key: SigningKey | None = None,
) -> MissionResult:
    """Build the mission's kit, fly it and write the report folder `out_dir` (`media`: plot and GIF too).

    `out_dir` must not exist or be empty: a report is never written over another
    (`drone_inspect_core.files.OutputDirError`; `claimed`: the caller already claimed it). A mission that
    cannot start (a bad checkpoint, a camera that does not open, a simulator that fails, an instruction
    refused) still leaves a report saying why, then raises. `signing_key`: a real vehicle's MAVLink
    signing key (`open_kit`).
    """
    out_dir = Path(out_dir) if claimed else claim_report_dir(out_dir)
    hold_reserve(out_dir)  # room for the outcome, before the flight's .tlog can fill the disk
    try:
        if rerun_path is not None:  # before anything starts: a recording is never overwritten
            from controller.missions.rerun_log import check_rerun_path

            rerun_path = check_rerun_path(rerun_path)
        with FlightSession(
            mission, out_dir, limits=limits, models=models, signing_key=signing_key, media=media,
            rerun_path=rerun_path,
        ) as session:  # fmt: skip
            session.fly()
        assert session.result is not None
        return session.result
    except BaseException as exc:
        if not (out_dir / REPORT_JSON).exists():  # it failed before the flight's own report began
            write_setup_failure(out_dir, mission, exc)
        raise
