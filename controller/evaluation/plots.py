"""Figures: training curves, accuracy heatmaps over the target offset (paper Fig. 3), failure gallery."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never a display
import matplotlib.pyplot as plt
import numpy as np
from PIL import Image

from drone_inspect_core.files import write_atomic


def plot_curves(history: Sequence[dict[str, float]], path: Path) -> None:
    """Loss terms and train/validation accuracy per epoch, side by side."""
    epochs = [h["epoch"] for h in history]
    fig, (ax_loss, ax_acc) = plt.subplots(1, 2, figsize=(10, 4))
    for key in ("total", "dir", "rank", "cons", "reg"):
        ax_loss.plot(epochs, [h[key] for h in history], label=key)
    ax_loss.set(xlabel="epoch", ylabel="loss", title="training losses", yscale="log")
    ax_loss.legend()
    ax_acc.plot(epochs, [h["train_accuracy"] for h in history], label="train")
    ax_acc.plot(epochs, [h["val_accuracy"] for h in history], label="validation")
    ax_acc.set(xlabel="epoch", ylabel="rank-1 accuracy", title="accuracy", ylim=(0, 1))
    ax_acc.legend()
    fig.tight_layout()
    _save(fig, path, dpi=100)


def plot_heatmaps(
    offsets_px: np.ndarray,
    correct: np.ndarray,
    x_correct: np.ndarray,
    z_correct: np.ndarray,
    epsilon_px: float,
    path: Path,
    bins: int = 12,
) -> None:
    """Mean accuracy (overall, horizontal, vertical) binned over the target's (du, dv) offset."""
    reach = float(np.abs(offsets_px).max()) if len(offsets_px) else 1.0
    edges = np.linspace(-reach, reach, bins + 1)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    for ax, values, title in zip(
        axes, (correct, x_correct, z_correct), ("overall", "horizontal (X)", "vertical (Z)"), strict=True
    ):
        hits, _, _ = np.histogram2d(offsets_px[:, 1], offsets_px[:, 0], bins=[edges, edges], weights=values)
        count, _, _ = np.histogram2d(offsets_px[:, 1], offsets_px[:, 0], bins=[edges, edges])
        with np.errstate(invalid="ignore", divide="ignore"):
            acc = hits / count
        im = ax.imshow(
            acc, origin="upper", extent=(-reach, reach, reach, -reach), vmin=0, vmax=1, cmap="viridis"
        )
        for e in (-epsilon_px, epsilon_px):
            ax.axvline(e, color="w", lw=0.8, ls="--")
            ax.axhline(e, color="w", lw=0.8, ls="--")
        ax.set(title=f"{title} accuracy", xlabel="du (px, right +)", ylabel="dv (px, down +)")
        fig.colorbar(im, ax=ax, fraction=0.046)
    fig.tight_layout()
    _save(fig, path, dpi=100)


def plot_gallery(images: Sequence[np.ndarray], captions: Sequence[str], path: Path, cols: int = 6) -> None:
    """A grid of RGB images with captions (e.g. 'true right/none · pred none/none')."""
    n = max(1, len(images))
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.9 * rows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, img, cap in zip(axes.ravel(), images, captions, strict=False):
        ax.imshow(img)
        h, w = img.shape[:2]
        ax.plot([w / 2], [h / 2], "r+", ms=10)
        ax.set_title(cap, fontsize=7)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=72)
    plt.close(fig)
    # Camera noise makes photographic PNGs large; a 128-colour palette keeps the gallery small.
    buffer.seek(0)
    with Image.open(buffer) as img:
        small = img.convert("RGB").quantize(colors=128)
    out = io.BytesIO()
    small.save(out, format="png", optimize=True)
    write_atomic(path, out.getvalue())


def _save(fig: plt.Figure, path: Path, dpi: int) -> None:
    """The figure as a PNG, whole or not at all (`write_atomic`), and closed."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    plt.close(fig)
    write_atomic(path, buffer.getvalue())
