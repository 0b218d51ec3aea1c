"""A contact sheet of a flown collection: one row of thumbnails per sector, each with its label's box.

Written at the end of a collection (`contact_sheet.png`) so that an operator sees at a glance what was
captured where: the goal images, the centre class, the eight sectors and the empty views, the tracked
box drawn green, a flagged capture's box red. The image centre's ε square is drawn on every thumbnail.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np

from drone_inspect_core.dataset import is_flagged
from drone_inspect_core.files import write_atomic

ROWS = ("goal", "centre", "N", "NE", "E", "SE", "S", "SW", "W", "NW", "none")
GREEN, RED, GREY = (60, 200, 60), (40, 40, 230), (200, 200, 200)  # BGR


def _thumbnail(root: Path, row: dict[str, Any], size: int, epsilon_px: float) -> np.ndarray:
    image = cv2.imread(str(root / row["image"]), cv2.IMREAD_COLOR)
    if image is None:
        return np.full((size, size, 3), 64, np.uint8)
    height, width = image.shape[:2]
    scale = size / max(width, height)
    thumb = cv2.resize(image, (round(width * scale), round(height * scale)), interpolation=cv2.INTER_AREA)
    cx, cy, e = width / 2 * scale, height / 2 * scale, epsilon_px * scale
    cv2.rectangle(thumb, (round(cx - e), round(cy - e)), (round(cx + e), round(cy + e)), GREY, 1)
    if row.get("bbox_px") is not None:
        u0, v0, u1, v1 = (round(v * scale) for v in row["bbox_px"])
        cv2.rectangle(thumb, (u0, v0), (u1, v1), RED if is_flagged(row) else GREEN, 1)
    canvas = np.full((size, size, 3), 32, np.uint8)
    canvas[: thumb.shape[0], : thumb.shape[1]] = thumb
    return canvas


def write_contact_sheet(
    root: Path, rows: list[dict[str, Any]], epsilon_px: float, path: Path, per_row: int = 10, size: int = 96
) -> Path | None:
    """The sheet as a PNG at `path` (None when there is nothing to show)."""
    groups: dict[str, list[dict[str, Any]]] = {name: [] for name in ROWS}
    for row in rows:
        key = "goal" if row["split"] == "goal" else row["sector"]
        groups.setdefault(key, []).append(row)
    lines = []
    label_w = 70
    for name, members in groups.items():
        if not members:
            continue
        picked = [
            members[round(i * (len(members) - 1) / max(1, per_row - 1))]
            for i in range(min(per_row, len(members)))
        ]
        tiles = [_thumbnail(root, row, size, epsilon_px) for row in picked]
        tiles += [np.full((size, size, 3), 32, np.uint8)] * (per_row - len(tiles))
        label = np.full((size, label_w, 3), 32, np.uint8)
        cv2.putText(label, name, (4, size // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.45, GREY, 1, cv2.LINE_AA)
        cv2.putText(label, f"{len(members)}", (4, size // 2 + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.4, GREY, 1)
        lines.append(np.hstack([label, *tiles]))
    if not lines:
        return None
    ok, png = cv2.imencode(".png", np.vstack(lines))
    if not ok:
        raise OSError(f"{path}: the contact sheet could not be encoded")
    write_atomic(path, png.tobytes())
    return path
