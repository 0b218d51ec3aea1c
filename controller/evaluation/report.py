"""The Markdown report of `dronectl reproduce`: Tables 2 and 3 beside the paper, Figure 3, failures."""

from __future__ import annotations

import datetime as dt
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from controller.evaluation.experiments import BY_NAME, MAIN, TABLE2, TABLE3
from controller.evaluation.plots import plot_gallery, plot_heatmaps
from controller.planning.actions import Action
from controller.training.config import PRESET_NOTES, PRESETS
from controller.training.data import load_index, read_image
from drone_inspect_core.files import write_atomic

# paper.tex Table 2: (vision generalisation, vision + text generalisation), mean ± std over 5 seeds.
PAPER_TABLE2: dict[str, tuple[str, str]] = {
    "fixed-cosine": ("70.5 ± 7.6", "71.0 ± 6.9"),
    "fixed-euclidean": ("67.5 ± 7.7", "68.0 ± 7.4"),
    "fixed-both": ("69.5 ± 6.7", "70.5 ± 5.4"),
    "varied-cosine": ("70.0 ± 6.1", "70.0 ± 6.1"),
    "varied-euclidean": ("68.5 ± 8.0", "69.5 ± 7.8"),
    "varied-both": ("70.5 ± 4.8", "70.5 ± 4.8"),
}
# paper.tex Table 3 (varied instructions, cosine, unseen images and instructions).
PAPER_TABLE3: dict[str, str] = {
    "varied-cosine": "70.0 ± 6.1 (Table 2)",
    "no-cons-reg": "68.5 ± 4.2",
    "no-dir": "72.0 ± 3.3",
    "no-rank": "12.0 ± 9.1",
}
ABLATION_LABELS = {
    "varied-cosine": "Full model",
    "no-cons-reg": "No Consistency/Regularization",
    "no-dir": "No Directional Loss",
    "no-rank": "No Ranking Loss",
}
GALLERY_MAX = 12


def _stat(values: Sequence[float]) -> str:
    """'mean ± std' in percent; std is the sample standard deviation (ddof = 1)."""
    v = 100.0 * np.asarray(values, dtype=float)
    std = float(v.std(ddof=1)) if len(v) > 1 else 0.0
    return f"{v.mean():.1f} ± {std:.1f}"


def _group(results: Sequence[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in results:
        groups[r["experiment"]].append(r)
    for runs in groups.values():
        runs.sort(key=lambda r: r["seed"])
    return groups


def _table2(groups: dict[str, list[dict[str, Any]]]) -> list[str]:
    lines = [
        "| Instruction | Distance | Vision gen. (ours) | paper | Vision + text gen. (ours) | paper "
        "| X / Z (ours, v+t) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for exp in TABLE2:
        runs = groups.get(exp.name)
        if not runs:
            continue
        paper_v, paper_vt = PAPER_TABLE2[exp.name]
        ours_v = _stat([r["train"]["rank1"] for r in runs])
        ours_vt = _stat([r["heldout"]["rank1"] for r in runs])
        x_acc = _stat([r["heldout"]["x_accuracy"] for r in runs])
        z_acc = _stat([r["heldout"]["z_accuracy"] for r in runs])
        lines.append(
            f"| {exp.instructions} | {exp.distance} | {ours_v} | {paper_v} | {ours_vt} | {paper_vt} "
            f"| {x_acc} / {z_acc} |"
        )
    return lines


def _table3(groups: dict[str, list[dict[str, Any]]]) -> list[str]:
    lines = ["| Ablation | Rank-1 (ours, v+t) | paper |", "| --- | --- | --- |"]
    for name in ("varied-cosine", *(e.name for e in TABLE3)):
        runs = groups.get(name)
        if runs:
            lines.append(
                f"| {ABLATION_LABELS[name]} | {_stat([r['heldout']['rank1'] for r in runs])} "
                f"| {PAPER_TABLE3[name]} |"
            )
    return lines


def _flat(prefix: str, value: Any) -> dict[str, Any]:
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        for k, v in value.items():
            out.update(_flat(f"{prefix}.{k}" if prefix else k, v))
        return out
    return {prefix: value}


def _settings(preset: str) -> list[str]:
    """The preset's notes and every setting in which it differs from the paper preset."""
    ours, paper = PRESETS[preset], PRESETS["paper"]
    a = _flat("", {"model": ours.model.to_dict(), "train": ours.train.to_dict()})
    b = _flat("", {"model": paper.model.to_dict(), "train": paper.train.to_dict()})
    lines = [f"Preset `{preset}`: {PRESET_NOTES[preset]}", ""]
    diff = [k for k in a if a[k] != b.get(k)]
    if diff:
        lines += ["| setting | this preset | paper preset |", "| --- | --- | --- |"]
        lines += [f"| `{k}` | {a[k]} | {b.get(k)} |" for k in diff]
    else:
        lines.append("All settings are the paper preset's.")
    return lines


def _per_kind(runs: Sequence[dict[str, Any]], data_dir: Path) -> list[str]:
    """Held-out rank-1 per target kind, mean ± std over seeds."""
    kind_of = {r.id: r.target_kind for r in load_index(data_dir).rows}
    per: dict[str, list[float]] = defaultdict(list)
    for run in runs:
        ev = run["heldout"]
        kinds = np.array([kind_of.get(i, "?") for i in ev["ids"]])
        ok = np.asarray(ev["predictions"]) == np.asarray(ev["labels"])
        for kind in sorted(set(kinds)):
            per[kind].append(float(ok[kinds == kind].mean()))
    lines = ["| target kind | test images | rank-1 (v+t) |", "| --- | --- | --- |"]
    n_of = {k: int(sum(kind_of.get(i) == k for i in runs[0]["heldout"]["ids"])) for k in per}
    lines += [f"| {k} | {n_of[k]} | {_stat(v)} |" for k, v in per.items()]
    return lines


def _figure3(runs: Sequence[dict[str, Any]], out_dir: Path) -> str:
    offsets = np.concatenate([np.asarray(r["heldout"]["offsets_px"]) for r in runs])
    pred = np.concatenate([np.asarray(r["heldout"]["predictions"]) for r in runs])
    true = np.concatenate([np.asarray(r["heldout"]["labels"]) for r in runs])
    path = out_dir / "figure3_heatmaps.png"
    plot_heatmaps(
        offsets,
        (pred == true).astype(float),
        (pred // 3 == true // 3).astype(float),
        (pred % 3 == true % 3).astype(float),
        float(runs[0]["epsilon_px"]),
        path,
    )
    return path.name


def _gallery(run: dict[str, Any], data_dir: Path, out_dir: Path) -> tuple[str, int]:
    ev = run["heldout"]
    rows = {r.id: r for r in load_index(data_dir).rows}
    fails = [i for i, (p, t) in enumerate(zip(ev["predictions"], ev["labels"], strict=True)) if p != t]
    images, captions = [], []
    for i in fails[:GALLERY_MAX]:
        row = rows[ev["ids"][i]]
        img = read_image(row.image, 224)
        du, dv = ev["offsets_px"][i]
        captions.append(
            f"true {Action.from_index(ev['labels'][i]).name}\n"
            f"pred {Action.from_index(ev['predictions'][i]).name}"
            f"\n(du, dv) = ({du:.1f}, {dv:.1f})"
        )
        images.append(img)
    path = out_dir / "failures.png"
    plot_gallery(images, captions, path)
    return path.name, len(fails)


def write_report(
    results: Sequence[dict[str, Any]], data_dir: Path, out_dir: Path, preset: str, seeds: int
) -> Path:
    """Write `report.md` (+ figures) into `out_dir` and return its path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    groups = _group(results)
    seconds = [r["train_seconds"] for r in results]
    lines = [
        "# Latent dynamics planner: the paper's experiments, reproduced",
        "",
        f"Generated {dt.datetime.now().isoformat(timespec='seconds')} by `dronectl reproduce` on "
        f"`{data_dir}`, preset `{preset}`, {seeds} seed(s) per experiment, "
        f"ε = {results[0]['epsilon_px']:.1f} px (dataset pixels). Accuracy is rank-1 (both axes right) "
        "on the held-out test scenes, mean ± sample std over seeds, in %. "
        "'Vision gen.' pairs each test image with a training-style instruction; 'Vision + text gen.' with a "
        "paraphrase never seen in training.",
        "",
        f"Training time per run: mean {np.mean(seconds):.0f} s, max {np.max(seconds):.0f} s "
        f"({len(results)} runs).",
        "",
        "## Settings",
        "",
        *_settings(preset),
        "",
        "## Table 2: instructions × distance",
        "",
        *_table2(groups),
        "",
        "## Table 3: loss ablations (varied instructions, cosine distance)",
        "",
        *_table3(groups),
        "",
    ]
    main_runs = groups.get(MAIN)
    if main_runs:
        gap = [100 * (r["train"]["rank1"] - r["heldout"]["rank1"]) for r in main_runs]
        lines += [
            f"Held-out minus training-style instructions ({MAIN}): "
            f"{-np.mean(gap):+.2f} points (per seed: {', '.join(f'{-g:+.2f}' for g in gap)}).",
            "",
            "Per target kind:",
            "",
            *_per_kind(main_runs, data_dir),
            "",
            "## Figure 3: accuracy over the target's offset from the image centre",
            "",
            f"All seeds of `{MAIN}`, held-out instructions; dashed lines at ±ε.",
            "",
            f"![heatmaps]({_figure3(main_runs, out_dir)})",
            "",
        ]
        name, n_fail = _gallery(main_runs[0], data_dir, out_dir)
        lines += [
            "## Failures",
            "",
            f"`{MAIN}`, seed {main_runs[0]['seed']}: {n_fail} of {main_runs[0]['heldout']['n']} "
            "test images wrong; "
            f"up to {GALLERY_MAX} shown (red + marks the image centre).",
            "",
            f"![failures]({name})",
            "",
        ]
    lines += [
        "## Runs",
        "",
        "| run | seed | vision | vision + text | train s |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in sorted(results, key=lambda r: (r["experiment"], r["seed"])):
        lines.append(
            f"| {r['experiment']} | {r['seed']} | {100 * r['train']['rank1']:.2f} | "
            f"{100 * r['heldout']['rank1']:.2f} | {r['train_seconds']:.0f} |"
        )
    path = out_dir / "report.md"
    write_atomic(path, "\n".join(lines) + "\n")
    assert all(r["experiment"] in BY_NAME for r in results)
    return path
