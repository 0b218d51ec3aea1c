"""The layout's rules, checked: imports point down the layers, the ground package imports nothing of ours,
only the simulator imports PyBullet and only flight/mavsdk imports mavsdk, `flight` reaches the
simulator only in its PyBullet backend, what flies never imports the research rooms (training,
evaluation, benchmarks), no import cycles, no two types of one name, and a real-vehicle mission loads
no simulator and no research module at all. A file over 400 lines is a warning for review, not a
failure: files split by concern, never by count. And docs/architecture.md, the map of it all, names
every module by its path, and every path, dotted module name and class it names exists.

The layers (docs/architecture.md): tools → controller → (perception, flight) → sim_world → core, where
`controller.planning` (deciding) never imports `controller.missions` (flying, reporting), and
perception and flight never import each other.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
import warnings
from collections import defaultdict
from functools import cache
from pathlib import Path

import cv2
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
CORE = "drone_inspect_core"
PACKAGES = (CORE, "sim_world", "flight", "perception", "controller", "dronectl")
ALLOWED: dict[str, set[str]] = {
    CORE: set(),
    "sim_world": {CORE},
    "flight": {CORE, "sim_world"},
    "perception": {CORE, "sim_world"},
    "controller": {CORE, "sim_world", "flight", "perception"},
    "dronectl": {CORE, "sim_world", "flight", "perception", "controller"},
}
FOLDERS = {"dronectl": Path("tools") / "dronectl"}
"""Where a package lives when not at the top: the command line's package is tools/dronectl."""
REVIEW_LINES = 400
RESEARCH_ROOMS = (
    "controller.training", "controller.evaluation", "controller.benchmarks",
    "perception.training", "perception.evaluation",
)  # fmt: skip
"""Training, evaluation, reproduction, plots and benchmarks: nothing that flies imports them."""


def is_research(module: str) -> bool:
    return any(module == room or module.startswith(room + ".") for room in RESEARCH_ROOMS)


def _modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        root = REPO / FOLDERS.get(package, Path(package))
        for path in root.rglob("*.py"):
            parts = (package, *path.relative_to(root).with_suffix("").parts)
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


def test_only_the_simulator_imports_pybullet_and_only_the_mavsdk_package_imports_mavsdk() -> None:
    pybullet = [m for m, p in MODULES.items() if any(i.split(".")[0] == "pybullet" for i in _imports(p, m))]
    mavsdk = [m for m, p in MODULES.items() if any(i.split(".")[0] == "mavsdk" for i in _imports(p, m))]
    assert pybullet and all(m.startswith("sim_world") for m in pybullet), pybullet
    assert mavsdk and all(m.startswith("flight.mavsdk.") for m in mavsdk), mavsdk


def test_flight_reaches_the_simulator_only_in_its_pybullet_backend() -> None:
    wrong = [
        f"{m} imports {i}"
        for m, p in MODULES.items()
        if m.startswith("flight") and m != "flight.pybullet_backend"
        for i in _imports(p, m)
        if i.split(".")[0] == "sim_world"
    ]
    assert not wrong, wrong


def test_what_flies_never_imports_the_research_rooms() -> None:
    wrong = [
        f"{m} imports {i}"
        for m, p in MODULES.items()
        if m.split(".")[0] in ("drone_inspect_core", "sim_world", "flight", "perception", "controller")
        and not is_research(m)
        for i in _imports(p, m)
        if is_research(i)
    ]
    assert not wrong, "\n".join(wrong)


def test_training_evaluation_reproduction_plots_and_benchmarks_live_in_the_research_rooms() -> None:
    """A module named for research work (training, evaluation, reproduction, plots, benchmarks) outside
    the rooms would fly with the product; the command line (`dronectl`) only calls into the rooms."""
    words = ("train", "evaluat", "reproduc", "plot", "bench")
    strays = [
        m
        for m in MODULES
        if m.split(".")[0] != "dronectl" and not is_research(m)
        and any(word in part for part in m.split(".")[1:] for word in words)
    ]  # fmt: skip
    assert not strays, strays
    assert all(is_research(m) for m in ("controller.evaluation.reproduce", "controller.evaluation.plots"))


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


def test_no_two_types_of_one_name_and_long_files_flagged_for_review() -> None:
    long = [
        f"{p.relative_to(REPO)}: {n}"
        for p in MODULES.values()
        if (n := len(p.read_text().splitlines())) > REVIEW_LINES
    ]
    if long:  # a reminder to look for a second idea in the file, never a reason to cut it up
        warnings.warn(f"files over {REVIEW_LINES} lines, for review: {long}", stacklevel=1)
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
    assert not [m for m in loaded if is_research(m)]


ARCHITECTURE_DOC = REPO / "docs" / "architecture.md"
_TOP = "|".join((*PACKAGES[:-1], "tools", "tests", "missions", "scenes", "docs"))
DOC_PATH = re.compile(rf"(?<![\w./-])((?:{_TOP})/[\w./-]*[\w/])")
DOC_DOTTED = re.compile(rf"(?<![\w./-])((?:{'|'.join(PACKAGES)})(?:\.[A-Za-z_]\w*)+)")
DOC_CLASS = re.compile(r"(?<![\w.])([A-Z][a-z0-9]+(?:[A-Z][a-z0-9]*)+)\b")
NOT_OURS = {"ProcessPoolExecutor", "ValueError", "DroneInspect"}
"""Names of other projects the page mentions in code spans (the Python library, Gymnasium's id)."""


@cache
def _top_level_names(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(t.id for t in targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
    return names


def _resolves(dotted: str) -> bool:
    """`pkg.module[.name]`: the longest module prefix exists, and what follows it is defined there."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        module = ".".join(parts[:k])
        if module in MODULES:
            return k == len(parts) or parts[k] in _top_level_names(MODULES[module])
    return False


def wrong_in_architecture_doc(text: str) -> list[str]:
    """What docs/architecture.md gets wrong: modules it does not name (by their path from the repository
    root), paths that do not exist, dotted names that do not resolve, classes nobody defines."""
    spans = re.findall(r"`([^`\n]+)`", text)
    wrong = [
        f"module not named: {rel}"
        for path in MODULES.values()
        if path.name != "__init__.py" and (rel := str(path.relative_to(REPO))) not in text
    ]
    paths = {p for span in spans for p in DOC_PATH.findall(span) if "<" not in span}
    wrong += [f"no such path: {p}" for p in sorted(paths) if not (REPO / p).exists()]
    dotted = {d for span in spans for d in DOC_DOTTED.findall(span)}
    wrong += [f"does not resolve: {d}" for d in sorted(dotted) if not _resolves(d)]
    defined = set().union(*(_top_level_names(p) for p in MODULES.values()))
    classes = {c for span in spans for c in DOC_CLASS.findall(span)} - NOT_OURS
    wrong += [f"defined nowhere: {c}" for c in sorted(classes) if c not in defined]
    return wrong


def test_the_architecture_page_names_every_module_and_only_what_exists() -> None:
    wrong = wrong_in_architecture_doc(ARCHITECTURE_DOC.read_text())
    assert not wrong, "\n".join(wrong)


def test_the_architecture_page_check_sees_what_drifted() -> None:
    text = ARCHITECTURE_DOC.read_text().replace("`flight/relay.py`", "`flight/relays.py`")
    text += "\n`controller.planning.loop.NoSuchLoop`, `FlyingCarpetVehicle`, `perception.no_module`\n"
    wrong = wrong_in_architecture_doc(text)
    assert "module not named: flight/relay.py" in wrong
    assert "no such path: flight/relays.py" in wrong
    assert "does not resolve: controller.planning.loop.NoSuchLoop" in wrong
    assert "does not resolve: perception.no_module" in wrong
    assert "defined nowhere: FlyingCarpetVehicle" in wrong
