"""The flown dataset on disk: the one dataset format (`drone_inspect_core.dataset`), written as captured.

A new collection claims its folder (`drone_inspect_core.files.claim_dir`: new or empty, never a folder
holding anything), writes `dataset.json` with `"complete": false` first, then each capture's PNG and its
manifest row (flushed at once), `goal.json` / `goal.png` and `plan.json` (the captures planned, so a
resumed collection flies exactly the ones not taken). `--resume` opens an incomplete flown dataset and
appends: every planned capture ends up exactly once. Images are named after their flight
(`images/f1_img_000042.png`), so nothing a flight wrote is ever written over, not even the image of a
capture whose row an interruption lost. Each flight's logs (.tlog, the simulator's log) go to
`flights/<n>/`.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from controller.collection.plan import PlannedCapture
from drone_inspect_core.dataset import (
    DATASET_JSON,
    FLOWN,
    IMAGES_DIR,
    MANIFEST,
    DatasetError,
    ManifestWriter,
    dataset_source,
    load_manifest,
)
from drone_inspect_core.files import OutputDirError, claim_dir, release_claim, write_json_atomic

log = logging.getLogger(__name__)

PLAN_JSON = "plan.json"
FLIGHTS_DIR = "flights"
PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 3]


class ResumeError(ValueError):
    """`--resume` of a folder that is not an incomplete flown dataset (the message says what it is)."""


class FlownDataset:
    """The dataset folder of one flown collection, new or resumed."""

    def __init__(self, root: Path, resume: bool) -> None:
        self.root = Path(root)
        self.meta: dict[str, Any] = {}
        self.taken: set[str] = set()
        self.rows: list[dict[str, Any]] = []
        if resume:
            self._open_existing()
        else:
            claim_dir(self.root, "--out folder")
            (self.root / IMAGES_DIR).mkdir()
            release_claim(self.root)  # images/ is in it: the folder is this collection's
        self.flight = len(self.meta.get("flights", []))
        self.flight_dir = self.root / FLIGHTS_DIR / str(self.flight)
        self.flight_dir.mkdir(parents=True, exist_ok=True)
        self._manifest = ManifestWriter(self.root, append=resume)

    def _open_existing(self) -> None:
        if not (self.root / DATASET_JSON).is_file():
            raise ResumeError(f"--resume {self.root}: no dataset.json there (start a collection with --out)")
        try:
            rows, meta = load_manifest(self.root, include_flagged=True)
        except DatasetError as exc:
            raise ResumeError(f"--resume {self.root}: {exc}") from None
        if dataset_source(meta) != FLOWN:
            raise ResumeError(f"--resume {self.root}: a {dataset_source(meta)} dataset, not a flown one")
        if meta.get("complete", True):
            raise ResumeError(f"--resume {self.root}: the collection is complete; nothing to resume")
        if not (self.root / PLAN_JSON).is_file():
            raise ResumeError(
                f"--resume {self.root}: no plan.json (the goal was never recorded): start again"
            )
        self._drop_torn_tail()
        self.meta, self.rows = meta, rows
        self.taken = {row["id"] for row in rows}

    def _drop_torn_tail(self) -> None:
        """An interruption may have left half a manifest line: cut it off (it recorded no whole row)."""
        path = self.root / MANIFEST
        data = path.read_bytes()
        if data and not data.endswith(b"\n"):
            keep = data[: data.rfind(b"\n") + 1]
            log.warning(
                "%s: cutting off a torn last line (%d bytes) before resuming", path, len(data) - len(keep)
            )
            with path.open("r+b") as file:
                file.truncate(len(keep))

    # --- the plan ---------------------------------------------------------------------------
    def save_plan(self, plan: list[PlannedCapture]) -> None:
        write_json_atomic(self.root / PLAN_JSON, {"captures": [c.as_dict() for c in plan]})

    def load_plan(self) -> list[PlannedCapture]:
        try:
            data = json.loads((self.root / PLAN_JSON).read_text(encoding="utf-8"))
            return [PlannedCapture.from_dict(c) for c in data["captures"]]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ResumeError(f"{self.root / PLAN_JSON}: unreadable: {exc}") from None

    # --- writing ------------------------------------------------------------------------------
    def write_meta(self, meta: dict[str, Any]) -> None:
        self.meta = meta
        write_json_atomic(self.root / DATASET_JSON, meta)

    def write_capture(self, capture_id: str, image_rgb: np.ndarray, row: dict[str, Any]) -> dict[str, Any]:
        """The PNG first, then its row (flushed): a row never names an image that is not on disk."""
        relative = f"{IMAGES_DIR}/f{self.flight}_{capture_id}.png"
        path = self.root / relative
        if path.exists():
            raise OutputDirError(f"{path}: already exists; nothing collected is ever written over")
        if not cv2.imwrite(str(path), cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR), PNG_PARAMS):
            raise OSError(f"{path}: the image could not be written")
        row = {"id": capture_id, "image": relative, **row}
        self._manifest.write([row])
        self.rows.append(row)
        self.taken.add(capture_id)
        return row

    def close(self) -> None:
        self._manifest.close()
