"""The ground floor: what every layer shares and none owns. It imports nothing of the project's.

- `frames`: ENU/NED, FLU/FRD and yaw conversions, in one place;
- `config_files`: reading and validating YAML configuration (scene and mission files);
- `dataset`: the dataset folder format (manifest, images, truth) that collection writes and
  perception and the planner read;
- `centring`: the ε rule, written once: the default ε and stopping margin, the offset of a
  detection, centred or not, the action label and the sector of an offset.
"""
