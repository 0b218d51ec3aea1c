"""The layout's rules, checked: imports point down the layers, the ground package imports nothing of ours,
only the simulator imports PyBullet and only the MAVSDK backend imports mavsdk, no import cycles, no
file over 400 lines, no two types of one name, and a real-vehicle mission loads no simulator at all.

The layers (docs/architecture.md): tools → controller → (perception, flight) → sim_world → core, where
`controller.planning` (deciding) never imports `controller.missions` (flying, reporting), and
perception and flight never import each other.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("core", "sim_world", "flight", "perception", "controller", "tools")
ALLOWED: dict[str, set[str]] = {
    "core": set(),
    "sim_world": {"core"},
    "flight": {"core", "sim_world"},
    "perception": {"core", "sim_world"},
    "controller": {"core", "sim_world", "flight", "perception"},
    "tools": {"core", "sim_world", "flight", "perception", "controller"},
}
MAX_LINES = 400


def _modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        for path in (REPO / package).rglob("*.py"):
            parts = path.relative_to(REPO).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


def _imports(path: Path, module: str, top_level_only: bool = False) -> set[str]:
    tree = ast.parse(path.read_text())
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    found: set[str] = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            if node.level:  # relative: resolve against the package
                base = module.split(".")[: -node.level] if path.name != "__init__.py" else module.split(".")
                found.add(".".join([*base, node.module]))
            else:
                found.add(node.module)
    return found


MODULES = _modules()


def test_imports_point_down_the_layers() -> None:
    wrong = []
    for module, path in MODULES.items():
        layer = module.split(".")[0]
        for imported in _imports(path, module):
            target = imported.split(".")[0]
            if target in PACKAGES and target != layer and target not in ALLOWED[layer]:
                wrong.append(f"{module} imports {imported}")
            if module.startswith("controller.planning") and imported.startswith("controller.missions"):
                wrong.append(f"{module} (deciding) imports {imported} (missions)")
    assert not wrong, "\n".join(wrong)


def test_only_the_simulator_imports_pybullet_and_only_the_mavsdk_backend_imports_mavsdk() -> None:
    pybullet = [m for m, p in MODULES.items() if any(i.split(".")[0] == "pybullet" for i in _imports(p, m))]
    mavsdk = [m for m, p in MODULES.items() if any(i.split(".")[0] == "mavsdk" for i in _imports(p, m))]
    assert pybullet and all(m.startswith("sim_world") for m in pybullet), pybullet
    assert sorted(mavsdk) == ["flight.mavsdk_backend", "flight.mavsdk_link"]


def test_only_core_onnx_runtime_imports_onnxruntime() -> None:
    users = [m for m, p in MODULES.items() if any(i.split(".")[0] == "onnxruntime" for i in _imports(p, m))]
    assert users == ["drone_inspect_core.onnx_runtime"], users


def test_no_import_cycles() -> None:
    graph = {m: {i for i in _imports(p, m, top_level_only=True) if i in MODULES} for m, p in MODULES.items()}
    state: dict[str, int] = {}
    cycles = []

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in graph[node]:
            if state.get(nxt) == 1:
                cycles.append(" -> ".join([*trail[trail.index(nxt) :], nxt]))
            elif nxt not in state:
                visit(nxt, [*trail, nxt])
        state[node] = 2

    for module in graph:
        if module not in state:
            visit(module, [module])
    assert not cycles, "\n".join(cycles)


def test_no_file_over_400_lines_and_no_two_types_of_one_name() -> None:
    long = [
        f"{p.relative_to(REPO)}: {n}"
        for p in MODULES.values()
        if (n := len(p.read_text().splitlines())) > MAX_LINES
    ]
    assert not long, long
    classes: dict[str, list[str]] = defaultdict(list)
    for module, path in MODULES.items():
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ClassDef):
                classes[node.name].append(module)
    assert not {name: where for name, where in classes.items() if len(where) > 1}


REAL_MISSION = """
import json, sys
from controller.missions.runner import run_mission
from controller.missions.schema import parse_mission
from flight.safety import FlightTimeouts, SafetyLimits
mission = parse_mission({"name": "real", "vehicle": "udpin://127.0.0.1:14698", "camera": sys.argv[1]})
limits = SafetyLimits(timeouts=FlightTimeouts(connect_s=0.5))
result = run_mission(mission, sys.argv[2], limits=limits, media=False)
print(json.dumps({"outcome": result.outcome, "error": result.error, "modules": sorted(sys.modules)}))
"""


@pytest.mark.slow
def test_a_real_vehicle_mission_loads_no_simulator_and_no_pybullet(tmp_path: Path) -> None:
    video = tmp_path / "camera.avi"  # a real stream, read by OpenCV as from a drone
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (96, 96))
    for i in range(30):
        writer.write(np.full((96, 96, 3), i * 8, np.uint8))
    writer.release()
    done = subprocess.run(
        [sys.executable, "-c", REAL_MISSION, f"file://{video}", str(tmp_path / "report")],
        cwd=REPO, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert "NO_AUTOPILOT" in (result["error"] or "")  # it really tried: camera open, vehicle asked for
    loaded = result["modules"]
    assert "pybullet" not in loaded
    assert not [m for m in loaded if m == "sim_world" or m.startswith("sim_world.")]
