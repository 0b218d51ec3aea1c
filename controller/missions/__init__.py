"""Missions: flying the deciding part on a vehicle, and judging and reporting what happened.

- `schema`: the mission file (validated YAML; its sections embed the types of the layers that use them);
- `setup`: what a mission's world is (scene, start, wind), shared by the kits;
- `kits/`: building a mission's vehicle, camera, detector and planner for each way to fly
  (`sim` in-process, `sim_mavlink`, `px4_sitl`, `ardupilot_sitl`, `real`; `open_kit`);
- `session`: one flight (connect, take off, the centring loop for each instruction, land, and the
  operator's hold/land/kill from any thread) and its report; `runner`: a mission flown as a session;
  `loop_setup`, `interrupts`, `truth`, `flight_results`: what the session uses;
- `results`: a flown mission as a row, and the judge of its expectations;
- `report`, `rerun_log`: the report folder and the Rerun recording; `suite`: many missions.
Benchmarks and the fault matrix fly missions too, from the research room `controller.benchmarks`.
"""
