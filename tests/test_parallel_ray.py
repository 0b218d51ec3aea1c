"""`--ray`: the same seeds give the same numbers on a local Ray of 2 CPUs as in plain local processes
(benchmark missions, a collection); a task whose worker dies is reported by name and the other
results are kept; the private Ray head is gone when its run is, SIGKILL included."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from controller.benchmarks.missions import BenchmarkConfig, run_benchmark
from drone_inspect_core.parallel import gather, task_executor

pytest.importorskip("ray", reason="the [distributed] extra (ray) is not installed")


@pytest.fixture(scope="module")
def ray_address():
    """One private 2-CPU Ray head for the tests that join a cluster by address (`--ray ADDRESS`)."""
    from drone_inspect_core.parallel import LocalRayHead, _refresh_ray_auth

    head = LocalRayHead(2).start()
    saved = {name: os.environ.get(name) for name in head.auth_env}
    os.environ.update(head.auth_env)
    _refresh_ray_auth()
    try:
        yield head.address
    finally:
        head.stop()
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
        _refresh_ray_auth()


COMPARED = (
    "name",
    "planner",
    "outcome",
    "steps",
    "moves",
    "final_truth_offset_px",
    "final_detector_offset_px",
)


def _rows(summary: dict) -> list[tuple]:
    return [tuple(m[k] for k in COMPARED) for m in summary["missions"]]


def _ps() -> list[tuple[int, int, str]]:
    out = subprocess.run(["ps", "-ww", "-eo", "pid=,sid=,args="], capture_output=True, text=True).stdout
    rows = []
    for line in out.splitlines():
        pid, sid, args = line.split(None, 2) if len(line.split(None, 2)) == 3 else (*line.split(), "")
        rows.append((int(pid), int(sid), args))
    return rows


@pytest.mark.slow
def test_benchmark_on_a_ray_cluster_gives_the_plain_numbers_and_a_dead_worker_is_named(
    tmp_path: Path, ray_address: str
) -> None:
    # The module's head (a private local head is what `--ray local` starts: the SIGKILL test's).
    config = BenchmarkConfig(n=3, seed=5, planners=("classic", "latent"))
    plain = run_benchmark(config)
    on_ray = run_benchmark(replace(config, parallel=2, ray=ray_address), report_dir=tmp_path / "reports")
    assert _rows(on_ray) == _rows(plain)
    assert len({m["name"] for m in on_ray["missions"]}) == 6
    assert not on_ray["limits"]["reports_incomplete"]

    with task_executor(2, ray=ray_address) as pool:
        # built-ins: Ray's workers cannot import a test module
        futures = [pool.submit(pow, 3, 2), pool.submit(os._exit, 7), pool.submit(pow, 4, 2)]
        results = gather(futures, lambda i: f"task {i} (seed {100 + i})")
    assert results[0] == 9 and results[2] == 16
    assert isinstance(results[1], Exception) and "died" in str(results[1]).lower()


@pytest.mark.slow
def test_collection_on_a_ray_cluster_writes_the_same_dataset(tmp_path: Path, ray_address: str) -> None:
    from sim_world.collection.collect import CollectConfig, collect

    def dataset(out: Path, ray: str | None) -> list[dict]:
        cfg = CollectConfig(
            out_dir=out, seed=3, n_goal=2, n_per_sector=1, n_test=2, n_empty=1, size_px=64, workers=2
        )
        collect(cfg, progress=False, ray=ray)
        return [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]

    plain, on_ray = dataset(tmp_path / "plain", None), dataset(tmp_path / "ray", ray_address)
    assert on_ray == plain and len(plain) == 2 + 8 + 2 + 1  # the same rows, in the same order
    for row in plain:  # the very same pixels
        assert (tmp_path / "plain" / row["image"]).read_bytes() == (
            tmp_path / "ray" / row["image"]
        ).read_bytes()
    assert json.loads((tmp_path / "ray" / "dataset.json").read_text())["complete"] is True


@pytest.mark.slow
def test_the_private_ray_head_dies_with_its_run_even_on_sigkill(tmp_path: Path) -> None:
    script = (
        "import time\n"
        "from drone_inspect_core.parallel import RayExecutor\n"
        "pool = RayExecutor('local', 1)\n"
        "print('TEMP', pool._head.temp_dir, flush=True)\n"
        "time.sleep(120)\n"
    )
    run = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        line = run.stdout.readline()
        assert line.startswith("TEMP "), line
        temp_dir = line.split(None, 1)[1].strip()
        # Ray's processes (GCS, raylet, agents, workers) share the session of `ray start`, which
        # names the temp folder on its command line; workers retitle themselves ("ray::IDLE").
        sessions = {
            sid for _, sid, args in _ps() if temp_dir in args and "drone_inspect_core.ray_head" not in args
        }
        assert sessions, "the head should be up"

        def left() -> list[str]:
            return [f"{pid} {args}" for pid, sid, args in _ps() if sid in sessions]

        assert len(left()) >= 3
        os.kill(run.pid, signal.SIGKILL)
        run.wait(timeout=10)
        deadline = time.monotonic() + 20
        while left() and time.monotonic() < deadline:
            time.sleep(0.5)
        assert not left(), left()
        assert not Path(temp_dir).exists()
    finally:
        if run.poll() is None:
            run.kill()


@pytest.mark.slow
def test_reproduce_on_a_ray_cluster_gives_the_numbers_of_local_processes(
    tmp_path: Path, ray_address: str
) -> None:
    from latent_synthetic import write_synthetic_dataset

    from controller.evaluation.reproduce import reproduce

    data = write_synthetic_dataset(tmp_path / "data", n_train=120, n_test=60, size=64)

    def rank1(out: Path, ray: str | None) -> list[tuple]:
        reproduce(data, out, seeds=2, experiments="main", epochs=1, workers=2, total_threads=2, ray=ray)
        rows = [json.loads(p.read_text()) for p in sorted(out.glob("runs/*/eval.json"))]
        return [(r["experiment"], r["seed"], r["train"]["rank1"], r["heldout"]["rank1"]) for r in rows]

    plain, on_ray = rank1(tmp_path / "plain", None), rank1(tmp_path / "ray", ray_address)
    assert len(plain) == 2 and on_ray == plain
    assert (tmp_path / "ray" / "report.md").is_file()
