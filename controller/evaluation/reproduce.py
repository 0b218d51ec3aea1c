"""`dronectl reproduce`: the paper's experiments (Tables 2 and 3, Figure 3) on a collected dataset.

Each experiment is (instructions, distance, loss weights) × seeds; each run trains one
checkpoint and evaluates it on the test split with training-style and held-out
instructions. Runs are independent, so they go to a process pool; a run whose folder
already holds `eval.json` is reused, so an interrupted reproduction resumes.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from tqdm import tqdm

from controller.evaluation.experiments import BY_NAME, EXPERIMENT_SETS, Experiment
from controller.training.config import run_configs
from drone_inspect_core.files import set_aside, write_json_atomic
from drone_inspect_core.parallel import gather, task_executor

log = logging.getLogger(__name__)
EVAL_FILE = "eval.json"
J = TypeVar("J")


@dataclass(frozen=True)
class Job:
    experiment: Experiment
    seed: int
    data_dir: Path
    run_dir: Path
    preset: str
    epochs: int | None
    threads: int


def run_job(job: Job) -> dict[str, Any]:
    """Train + evaluate one (experiment, seed); returns (and stores) the evaluation summary."""
    from controller.evaluation.evaluate import evaluate_loaded
    from controller.planning.latent.checkpoint import load_checkpoint
    from controller.training.data import load_images, load_index
    from controller.training.train import train

    done = job.run_dir / EVAL_FILE
    if done.is_file():
        return json.loads(done.read_text())
    exp = job.experiment
    cfg = run_configs(
        job.preset,
        distance=exp.distance,
        instructions=exp.instructions,
        seed=job.seed,
        weights=exp.weights(job.preset),
        epochs=job.epochs,
        threads=job.threads,
    )
    if (kept := set_aside(job.run_dir)) is not None:  # an interrupted run: kept, and trained afresh
        log.warning("%s was not finished: kept as %s, training it again", job.run_dir, kept)
    result = train(job.data_dir, job.run_dir, cfg.model, cfg.train, progress=False)
    ckpt = load_checkpoint(job.run_dir)
    index = load_index(job.data_dir)
    test = load_images(
        index.split("test"), ckpt.config.image_size, float(ckpt.meta["epsilon_px"]), desc="test"
    )
    summary: dict[str, Any] = {
        "experiment": exp.name,
        "seed": job.seed,
        "train_seconds": result.seconds,
        "best_val_accuracy": result.best_val_accuracy,
        "epsilon_px": ckpt.meta["epsilon_px"],
    }
    for setting in ("train", "heldout"):
        ev = evaluate_loaded(ckpt, test, setting, seed=job.seed)
        summary[setting] = ev.__dict__
    write_json_atomic(done, summary, indent=None)
    return summary


def run_jobs(
    jobs: Sequence[J],
    fn: Callable[[J], dict[str, Any]],
    label: Callable[[J], str],
    workers: int,
    ray: str | None,
    desc: str,
) -> tuple[list[dict[str, Any]], list[str]]:
    """Run `fn` on every job, in this process (`workers` 1, no Ray) or on a pool; returns the results of
    those that finished and a line naming each one that failed (its label and the error)."""
    with task_executor(workers, ray) as pool, tqdm(total=len(jobs), desc=desc) as bar:
        if pool is None:
            done: list[dict[str, Any] | BaseException] = []
            for job in jobs:
                done.append(fn(job))
                bar.update(1)
        else:
            futures = [pool.submit(fn, job) for job in jobs]
            done = gather(futures, lambda i: label(jobs[i]), bar)
    results = [r for r in done if not isinstance(r, BaseException)]
    failed = [f"{label(job)}: {type(r).__name__}: {r}"
              for job, r in zip(jobs, done, strict=True) if isinstance(r, BaseException)]  # fmt: skip
    return results, failed


class ReproduceTaskError(RuntimeError):
    """Some training runs failed on their workers; the report holds the others."""


def reproduce(
    data_dir: Path,
    out_dir: Path,
    *,
    seeds: int = 5,
    preset: str = "cpu",
    workers: int = 1,
    experiments: str = "all",
    epochs: int | None = None,
    total_threads: int = 2,
    ray: str | None = None,
) -> Path:
    """Run the chosen experiment set over `seeds` seeds and write `out_dir/report.md`."""
    from controller.evaluation.report import write_report

    if experiments not in EXPERIMENT_SETS:
        raise ValueError(f"unknown experiment set {experiments!r}; choose one of {sorted(EXPERIMENT_SETS)}")
    out_dir = Path(out_dir)
    threads = max(1, total_threads // max(1, workers))
    jobs = [
        Job(
            BY_NAME[name], seed, Path(data_dir), out_dir / "runs" / f"{name}_s{seed}", preset, epochs, threads
        )
        for name in EXPERIMENT_SETS[experiments]
        for seed in range(seeds)
    ]
    results, failed = run_jobs(
        jobs, run_job, lambda job: f"{job.experiment.name} seed {job.seed}", workers, ray, "runs"
    )
    for summary in results:
        log.info(
            "%s seed %d: held-out rank-1 %.4f",
            summary["experiment"],
            summary["seed"],
            summary["heldout"]["rank1"],
        )
    if failed and not results:
        raise ReproduceTaskError("every run failed: " + "; ".join(failed))
    report = write_report(results, Path(data_dir), out_dir, preset, seeds)
    if failed:
        raise ReproduceTaskError(
            f"{len(failed)} of {len(jobs)} runs failed (the report holds the others; rerun to finish them, "
            "finished runs are kept): " + "; ".join(failed)
        )
    return report
