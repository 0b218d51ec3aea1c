"""Missions: flying the deciding part on a vehicle, and judging and reporting what happened.

- `schema`: the mission file (validated YAML) and its options (`schema_options`: PX4, faults);
- `setup`: what a mission's world is (scene, start, wind, link faults), shared by the kits;
- `kits/`: building a mission's vehicle, camera, detector and planner for each way to fly
  (`sim` in-process, `mavlink`: sim-vehicle and a real vehicle, `px4_sitl`);
- `session`: one flight (connect, take off, the centring loop for each instruction, land, and the
  operator's hold/land/kill from any thread) and its report; `runner`: a mission flown as a session;
- `results`: a flown mission as a row, and the judge of its expectations;
- `report`: the report folder; `suite`, `benchmark`, `fault_matrix`: many missions.
"""
