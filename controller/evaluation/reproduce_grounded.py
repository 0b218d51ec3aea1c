"""`dronectl reproduce --experiments grounded`: the instruction-chooses-the-target experiment over seeds.

Per seed, train the `grounded` preset on the training folders together (as the shipped checkpoint
is trained) and evaluate it on every test folder with held-out phrasings and synonyms: rank-1,
rank-1 by targets in view, and the "not in view" AUROC. The report gives each figure's mean and
spread over seeds, since one seed's figure moves by a few points, and the held-out look's gap to
in-distribution images with the same number of targets in view, and with the same named kind as well
(the `--heldout-look` folder against the test folders without twins; twins are a harder family of
their own, so they would flatter the gap).

A seed whose folder already holds `eval.json` is reused; one whose folder holds a finished training
run (`metrics.json` beside the checkpoint) is evaluated without retraining, so an interrupted
reproduction resumes, and the shipped checkpoint's own run can stand in for its seed.
"""

from __future__ import annotations

import json
import logging
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from controller.training.config import run_configs
from drone_inspect_core.files import set_aside, write_json_atomic

log = logging.getLogger(__name__)
EVAL_FILE = "eval.json"
REPORT_FILE = "grounded.md"
SUMMARY_FILE = "grounded.json"
LOOK = "heldout-look"
MODES = (("tests", "look_gap", False), ("tests_mirror", "look_gap_mirror", True))
"""Each test set is scored as the image alone and with its mirror image (`evaluate --mirror-tta`, what
the planner does where its checkpoint asks for it)."""
STRATA = (
    ("by_targets_in_view", "", "the same number of targets in view"),
    ("by_kind_and_targets", "_kind", "the same named kind and the same number of targets in view"),
)
"""How the held-out look is matched to in-distribution images: (the evaluation's grouping, the suffix
of its gap key in the summary, words for the report). Matching on the named kind as well keeps a
test set's draw of kinds (switch boxes are the hardest kind everywhere) out of the look's gap."""


@dataclass(frozen=True)
class GroundedJob:
    seed: int
    train_dirs: tuple[Path, ...]
    tests: tuple[tuple[str, Path], ...]
    """(name, folder) of every test set; the held-out look is named `LOOK`."""
    run_dir: Path
    epochs: int | None
    threads: int
    model_overrides: tuple[tuple[str, Any], ...] = ()
    """Changes to the preset's model (tests use a tiny one); empty for the real experiment."""
    train_overrides: tuple[tuple[str, Any], ...] = ()
    """Changes to the preset's training (a recipe under test, e.g. `shift_init_std`); empty: the preset's."""


def named_test_sets(tests: Sequence[Path], heldout_look: Path | None) -> tuple[tuple[str, Path], ...]:
    """Name every test folder by its folder name (the held-out look: `LOOK`); names must be distinct."""
    named = [(Path(t).name, Path(t)) for t in tests]
    if heldout_look is not None:
        named.append((LOOK, Path(heldout_look)))
    names = [n for n, _ in named]
    if len(set(names)) != len(names):
        raise ValueError(f"test folders need distinct names, got {names}")
    if not named:
        raise ValueError("no test folder: give --test and/or --heldout-look")
    return tuple(named)


def run_grounded_job(job: GroundedJob) -> dict[str, Any]:
    """Train (unless finished) and evaluate one seed; returns (and stores) its summary."""
    from controller.evaluation.evaluate import evaluate_checkpoint_modes
    from controller.training.train import METRICS_FILE, train

    done = job.run_dir / EVAL_FILE
    metrics_path = job.run_dir / METRICS_FILE
    if done.is_file():
        if metrics_path.is_file():
            check_run_recipe(job, json.loads(metrics_path.read_text()))
        return json.loads(done.read_text())
    if not metrics_path.is_file():
        cfg = run_configs(
            "grounded",
            seed=job.seed,
            epochs=job.epochs,
            threads=job.threads,
            model_overrides=dict(job.model_overrides),
            train_overrides=dict(job.train_overrides),
        )
        if (kept := set_aside(job.run_dir)) is not None:  # an interrupted run: kept, and trained afresh
            log.warning("%s was not finished: kept as %s, training it again", job.run_dir, kept)
        train(list(job.train_dirs), job.run_dir, cfg.model, cfg.train, progress=False)
    metrics = json.loads(metrics_path.read_text())
    check_run_recipe(job, metrics)
    summary: dict[str, Any] = {
        "seed": job.seed,
        "train_seconds": metrics["seconds"],
        "epochs": metrics["train"]["epochs"],
        "best_val_accuracy": metrics["best_val_accuracy"],
        "model_overrides": dict(job.model_overrides),
        "train_overrides": dict(job.train_overrides),
    }
    for key, _, _ in MODES:
        summary[key] = {}
    modes = [mirror for _, _, mirror in MODES]
    for name, folder in job.tests:
        twins = _has_twins(folder)
        results = evaluate_checkpoint_modes(job.run_dir, folder, "heldout", mirror_modes=modes)
        for (key, _, _), ev in zip(MODES, results, strict=True):
            summary[key][name] = {
                "rank1": ev.rank1,
                "n": ev.n,
                "by_targets_in_view": ev.by_targets_in_view,
                "by_kind_and_targets": ev.by_kind_and_targets,
                "auroc": None if ev.presence is None else ev.presence.get("auroc"),
                "twins": twins,
            }
    write_json_atomic(done, summary, indent=None)
    return summary


def check_run_recipe(job: GroundedJob, metrics: dict[str, Any]) -> None:
    """Refuse a finished run (trained here, or a run folder copied in to be evaluated) whose seed, or a
    setting the job changes, is not what the job asks for: its figures would be reported as another
    recipe's. `metrics`: the run's `metrics.json`."""
    wanted = [("train", "seed", job.seed), *(("model", k, v) for k, v in job.model_overrides)]
    wanted += [("train", k, v) for k, v in job.train_overrides]
    for part, key, value in wanted:
        held = metrics.get(part, {}).get(key)
        if held != value and str(held) != str(value):
            raise ValueError(
                f"{job.run_dir}: a finished run with {part} {key} = {held!r}, but this reproduction "
                f"asks for {value!r} (seed {job.seed}): move it aside or give the recipe it was trained with"
            )


def _has_twins(folder: Path) -> bool:
    meta = json.loads((Path(folder) / "dataset.json").read_text())
    return bool(meta.get("protocol", {}).get("twins", False))


def look_gap(
    summary: dict[str, Any], key: str = "tests", by: str = "by_targets_in_view"
) -> dict[str, float] | None:
    """One seed's held-out look rank-1 against the no-twins test sets' rank-1 in the same group (`by`:
    targets in view, or named kind and targets in view), weighted by the held-out set's own mix of
    groups; None without a held-out look (or an evaluation from before that grouping existed)."""
    tests = summary[key]
    look = tests.get(LOOK)
    if look is None or by not in look:
        return None
    refs = [t for name, t in tests.items() if name != LOOK and not t["twins"] and by in t]
    reference = weight = 0.0
    for k, cell in look[by].items():
        cells = [t[by][k] for t in refs if k in t[by]]
        n = sum(c["n"] for c in cells)
        if n == 0:
            continue  # no in-distribution image with this many targets: not compared
        reference += cell["n"] * sum(c["rank1"] * c["n"] for c in cells) / n
        weight += cell["n"]
    if weight == 0:
        return None
    matched_look = sum(
        cell["rank1"] * cell["n"] for k, cell in look[by].items() if any(k in t[by] for t in refs)
    )
    return {"heldout": matched_look / weight, "in_distribution": reference / weight}


def reproduce_grounded(
    train_dirs: Sequence[Path],
    tests: Sequence[Path],
    heldout_look: Path | None,
    out_dir: Path,
    *,
    seeds: int = 3,
    workers: int = 1,
    epochs: int | None = None,
    total_threads: int = 2,
    ray: str | None = None,
    model_overrides: dict[str, Any] | None = None,
    train_overrides: dict[str, Any] | None = None,
) -> Path:
    """Run `seeds` seeds and write `out_dir/grounded.md` (and `grounded.json`); returns the report's path."""
    from controller.evaluation.reproduce import ReproduceTaskError, run_jobs

    out_dir = Path(out_dir)
    named_tests = named_test_sets(tests, heldout_look)
    threads = max(1, total_threads // max(1, workers))
    jobs = [
        GroundedJob(seed, tuple(Path(d) for d in train_dirs), named_tests,
                    out_dir / "runs" / f"grounded_s{seed}", epochs, threads,
                    tuple(sorted((model_overrides or {}).items())),
                    tuple(sorted((train_overrides or {}).items())))
        for seed in range(seeds)
    ]  # fmt: skip
    results, failed = run_jobs(jobs, run_grounded_job, lambda job: f"seed {job.seed}", workers, ray, "seeds")
    if not results:
        raise ReproduceTaskError("every run failed: " + "; ".join(failed))
    out_dir.mkdir(parents=True, exist_ok=True)
    table = summarise(results)
    write_json_atomic(out_dir / SUMMARY_FILE, {"seeds": results, "summary": table})
    report = out_dir / REPORT_FILE
    report.write_text(render_report(table, results, train_dirs, named_tests))
    print(render_report(table, results, train_dirs, named_tests))
    if failed:
        raise ReproduceTaskError(f"{len(failed)} of {len(jobs)} seeds failed: " + "; ".join(failed))
    return report


def _spread(values: list[float]) -> dict[str, float]:
    return {
        "mean": statistics.fmean(values),
        "sd": statistics.stdev(values) if len(values) > 1 else 0.0,
        "min": min(values),
        "max": max(values),
    }


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean, sd, min and max over seeds of every test set's rank-1 and AUROC, and of the look gap, for
    each scoring mode (`MODES`: "tests", "tests_mirror"; the latter's gap is "look_gap_mirror")."""
    table: dict[str, Any] = {"seeds": [r["seed"] for r in results]}
    for key, gap_key, _ in MODES:
        if key not in results[0]:
            continue  # an eval.json from before the mirror mode
        table[key] = {}
        for name in results[0][key]:
            cells = [r[key][name] for r in results]
            aurocs = [c["auroc"] for c in cells if c["auroc"] is not None]
            table[key][name] = {
                "n": cells[0]["n"],
                "rank1": _spread([c["rank1"] for c in cells]),
                "auroc": _spread(aurocs) if aurocs else None,
            }
        for by, suffix, _ in STRATA:
            gaps = [g for g in (look_gap(r, key, by) for r in results) if g is not None]
            if gaps:
                table[gap_key + suffix] = {
                    "heldout": _spread([g["heldout"] for g in gaps]),
                    "in_distribution": _spread([g["in_distribution"] for g in gaps]),
                    "gap_points": _spread([100 * (g["in_distribution"] - g["heldout"]) for g in gaps]),
                }
    table["train_seconds"] = _spread([r["train_seconds"] for r in results])
    return table


def _pct(s: dict[str, float]) -> str:
    return f"{100 * s['mean']:.2f} % ± {100 * s['sd']:.2f} ({100 * s['min']:.2f}–{100 * s['max']:.2f})"


def render_report(
    table: dict[str, Any],
    results: list[dict[str, Any]],
    train_dirs: Sequence[Path],
    tests: Sequence[tuple[str, Path]],
) -> str:
    seeds = ", ".join(str(s) for s in table["seeds"])
    changed = sorted(
        {
            f"{k} = {v}"
            for r in results
            for k, v in [*(r.get("model_overrides") or {}).items(), *(r.get("train_overrides") or {}).items()]
        }
    )
    recipe = "`--preset grounded`" + (f" ({', '.join(changed)})" if changed else "")
    lines = [
        "# The instruction chooses the target: the grounded preset over seeds",
        "",
        f"Trained on {', '.join(str(d) for d in train_dirs)} with {recipe}; seeds {seeds}. "
        "Held-out phrasings and synonyms on every test set. Mean ± sd over seeds (min–max).",
    ]
    titles = {"tests": "Each image alone", "tests_mirror": "With its mirror image (`--mirror-tta`)"}
    for key, gap_key, _ in MODES:
        if key not in table:
            continue
        lines += [
            "",
            f"## {titles[key]}",
            "",
            "| test set | images | rank-1 | not in view: AUROC | per seed |",
            "| --- | --- | --- | --- | --- |",
        ]
        for name, folder in tests:
            cell = table[key][name]
            auroc = (
                "" if cell["auroc"] is None else f"{cell['auroc']['mean']:.3f} ± {cell['auroc']['sd']:.3f}"
            )
            per_seed = " / ".join(f"{100 * r[key][name]['rank1']:.2f}" for r in results)
            lines.append(
                f"| {name} (`{folder}`) | {cell['n']} | {_pct(cell['rank1'])} | {auroc} | {per_seed} |"
            )
        for _, suffix, words in STRATA:
            gap = table.get(gap_key + suffix)
            if gap:
                lines += [
                    "",
                    f"Held-out look against in-distribution test images (no twins) with {words}, "
                    "weighted by the held-out set's mix:",
                    "",
                    f"- held-out look: {_pct(gap['heldout'])}",
                    f"- in distribution: {_pct(gap['in_distribution'])}",
                    f"- gap: {gap['gap_points']['mean']:.2f} points ± {gap['gap_points']['sd']:.2f} "
                    f"({gap['gap_points']['min']:.2f} to {gap['gap_points']['max']:.2f})",
                ]
    t = table["train_seconds"]
    lines += ["", f"Training: {t['mean']:.0f} s per seed on average ({t['min']:.0f}–{t['max']:.0f} s).", ""]
    return "\n".join(lines)
