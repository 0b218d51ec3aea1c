"""The dataset folder on disk: `dataset.json`, `manifest.jsonl`, `images/*.png`.

Written by `sim_world.collection.collect`, read by perception and the controller through
`load_manifest`. The manifest stores truth only (target centre and bbox in pixels,
drone pose, scene parameters, split, sector); labels are derived from the offsets
with `controller.planning.actions.label_from_offset`, so ε can change without re-rendering.

A row's own truth fields are the *named* target's (the one the instruction names and the
protocol centres). Since scenes may hold several targets, a row also carries
`target_attribute` (the named target's trim colour name), `named` (its index in `targets`)
and `targets` (every target's kind, attribute and truth). Datasets written before hold
none of these and still load; `row_targets(row)` gives the list for either.

Writing is crash-tolerant: `dataset.json` is written (atomically) before the first
image with `"complete": false` and rewritten at the end; each manifest row is
flushed as soon as its PNG is on disk, so an interrupted collection leaves a
readable dataset of everything written so far.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TextIO

import cv2
import numpy as np

from drone_inspect_core.targets import colour_name

logger = logging.getLogger(__name__)

GENERATOR_VERSION = "sim_world.collect/2"  # a format id (kept when code moves); 2: floor plane not drawn
DATASET_JSON = "dataset.json"
MANIFEST = "manifest.jsonl"
IMAGES_DIR = "images"

SPLITS = ("goal", "train", "test", "empty")
SECTORS = ("N", "NE", "E", "SE", "S", "SW", "W", "NW", "centre", "none")

_TRUTH_FIELDS: dict[str, type | tuple[type, ...]] = {
    "centre_px": list,
    "offset_px": list,
    "bbox_px": (list, type(None)),
    "in_view": bool,
    "fully_in_view": bool,
    "visible_fraction": (int, float),
    "depth_m": (int, float),
}
"""Where one target is in the image: the row's own (the named target's) and each `targets` entry's."""
_ROW_FIELDS: dict[str, type | tuple[type, ...]] = {
    "id": str,
    "image": str,
    "split": str,
    "sector": str,
    "scene_seed": int,
    "target_kind": str,
    **_TRUTH_FIELDS,
    "drone": dict,
    "offset_m": dict,
    "scene": dict,
}
_TARGET_FIELDS: dict[str, type | tuple[type, ...]] = {"kind": str, "attribute": str, **_TRUTH_FIELDS}
"""Each entry of a row's optional `targets` list."""
_META_FIELDS = ("generator_version", "seed", "camera", "scene_config", "counts")


class DatasetError(ValueError):
    """A dataset folder that cannot be read; the message names the file (and line or field)."""


def read_image_rgb(path: Path) -> np.ndarray:
    """A dataset image as RGB uint8 in its own size; DatasetError naming the file if unreadable."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise DatasetError(f"{path}: not a readable image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def read_rgb(path: Path, size: int) -> np.ndarray:
    """A dataset image as RGB uint8 (size, size, 3), area-resized; DatasetError if unreadable."""
    rgb = read_image_rgb(path)
    if rgb.shape[:2] != (size, size):
        rgb = cv2.resize(rgb, (size, size), interpolation=cv2.INTER_AREA)
    return rgb


def write_json_atomic(path: Path, data: dict[str, Any]) -> None:
    """Write JSON through a temporary file and a rename, so readers never see half a file."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, path)


class ManifestWriter:
    """Appends manifest rows, one flushed line each (context manager)."""

    def __init__(self, out_dir: Path) -> None:
        self.path = out_dir / MANIFEST
        self._file: TextIO = self.path.open("w", encoding="utf-8")
        self.rows_written = 0

    def write(self, rows: Iterable[dict[str, Any]]) -> None:
        for row in rows:
            self._file.write(json.dumps(row, separators=(",", ":")) + "\n")
            self.rows_written += 1
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()

    def __enter__(self) -> ManifestWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def prepare_output_dir(out_dir: Path) -> None:
    """Create the folder and `images/`; refuse a folder that already holds a dataset."""
    if out_dir.exists() and not out_dir.is_dir():
        raise DatasetError(f"{out_dir}: exists and is not a folder")
    if (out_dir / MANIFEST).exists() or (out_dir / DATASET_JSON).exists():
        raise DatasetError(f"{out_dir}: already holds a dataset; choose another --out or remove it first")
    (out_dir / IMAGES_DIR).mkdir(parents=True, exist_ok=True)


def _check_fields(
    row: dict[str, Any], fields: dict[str, type | tuple[type, ...]], where: str, prefix: str = ""
) -> None:
    for name, kind in fields.items():
        if name not in row:
            raise DatasetError(f"{where}: missing field {prefix + name!r}")
        value = row[name]
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            raise DatasetError(
                f"{where}: field {prefix + name!r} has the wrong type ({type(value).__name__})"
            )


def _check_targets(row: dict[str, Any], where: str) -> None:
    """The optional several-target fields: all three or none, `named` indexing `targets`."""
    present = [name for name in ("target_attribute", "named", "targets") if name in row]
    if not present:
        return  # a dataset written before scenes held several targets
    if len(present) != 3:
        missing = sorted({"target_attribute", "named", "targets"} - set(present))
        raise DatasetError(f"{where}: field {missing[0]!r} missing beside {present}")
    targets, named = row["targets"], row["named"]
    if not isinstance(row["target_attribute"], str):
        raise DatasetError(f"{where}: field 'target_attribute' has the wrong type")
    if not isinstance(targets, list) or not targets:
        raise DatasetError(f"{where}: field 'targets' must be a non-empty list")
    if not isinstance(named, int) or isinstance(named, bool) or not 0 <= named < len(targets):
        raise DatasetError(
            f"{where}: field 'named' must index 'targets' (0..{len(targets) - 1}), got {named!r}"
        )
    for i, entry in enumerate(targets):
        if not isinstance(entry, dict):
            raise DatasetError(f"{where}: field 'targets[{i}]' must be a JSON object")
        _check_fields(entry, _TARGET_FIELDS, where, prefix=f"targets[{i}].")


def row_targets(row: dict[str, Any]) -> list[dict[str, Any]]:
    """Every target's kind, attribute and truth in a row, the named one at `row.get("named", 0)`.

    A row from before several-target scenes has no `targets`: its one target is built from the
    row's own fields (the attribute named from the scene's sampled bezel colour, when recorded).
    """
    if "targets" in row:
        return row["targets"]
    bezel = row.get("scene", {}).get("target", {}).get("bezel_colour")
    attribute = colour_name(bezel) if isinstance(bezel, str) else None
    return [{"kind": row["target_kind"], "attribute": attribute, **{k: row[k] for k in _TRUTH_FIELDS}}]


def _check_row(row: object, where: str) -> dict[str, Any]:
    if not isinstance(row, dict):
        raise DatasetError(f"{where}: expected a JSON object, got {type(row).__name__}")
    _check_fields(row, _ROW_FIELDS, where)
    _check_targets(row, where)
    if row["split"] not in SPLITS:
        raise DatasetError(f"{where}: field 'split' is {row['split']!r}, expected one of {SPLITS}")
    if row["sector"] not in SECTORS:
        raise DatasetError(f"{where}: field 'sector' is {row['sector']!r}, expected one of {SECTORS}")
    for name in ("centre_px", "offset_px"):
        if len(row[name]) != 2:
            raise DatasetError(f"{where}: field {name!r} must hold 2 numbers")
    if row["bbox_px"] is not None and len(row["bbox_px"]) != 4:
        raise DatasetError(f"{where}: field 'bbox_px' must hold 4 numbers or be null")
    return row


def load_manifest(
    directory: str | Path, check_images: bool = True
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Read a dataset folder: (manifest rows in file order, the `dataset.json` contents).

    Raises `DatasetError` naming the file and line for a missing folder, a missing or
    malformed `dataset.json`, a corrupt manifest line or a row whose image is missing.
    An interrupted collection (`"complete": false`) loads with a warning, and a torn
    final line it may have left is skipped.
    """
    root = Path(directory)
    if not root.is_dir():
        raise DatasetError(f"{root}: no such dataset folder")
    meta_path = root / DATASET_JSON
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DatasetError(
            f"{meta_path}: missing (is {root} a dataset written by `dronectl collect`?)"
        ) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DatasetError(f"{meta_path}: unreadable: {exc}") from None
    if not isinstance(meta, dict):
        raise DatasetError(f"{meta_path}: expected a JSON object")
    for name in _META_FIELDS:
        if name not in meta:
            raise DatasetError(f"{meta_path}: missing field {name!r}")
    complete = bool(meta.get("complete", True))

    manifest_path = root / MANIFEST
    try:
        lines = manifest_path.read_text(encoding="utf-8").split("\n")
    except FileNotFoundError:
        raise DatasetError(f"{manifest_path}: missing") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{manifest_path}: unreadable: {exc}") from None
    torn_tail = lines[-1] != ""  # every complete row ends with a newline
    rows: list[dict[str, Any]] = []
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        where = f"{manifest_path}:{number}"
        try:
            row = json.loads(line)
        except json.JSONDecodeError as exc:
            if not complete and torn_tail and number == len(lines):
                logger.warning("%s: skipping a torn last line left by an interrupted collection", where)
                break
            raise DatasetError(f"{where}: not valid JSON ({exc.msg})") from None
        row = _check_row(row, where)
        if check_images and not (root / row["image"]).is_file():
            raise DatasetError(f"{where}: image {row['image']!r} is missing")
        rows.append(row)
    if not complete:
        logger.warning("%s: the collection was interrupted; %d rows are usable", root, len(rows))
    return rows, meta
