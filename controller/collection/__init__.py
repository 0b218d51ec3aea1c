"""The paper's collection protocol flown through the Vehicle interface (`dronectl collect --vehicle ...`).

The same code flies a simulated vehicle (sim-mavlink, px4-sitl) and a real one: record the goal pose,
capture goal images around it, fly sector poses inside a box around it, capture each once settled, and
label every capture from the image (the target's box tracked from the goal image) checked against the
pose geometry. Writes the one dataset format (`drone_inspect_core.dataset`). docs/own-target.md.
"""
