"""The dataset folder on disk: `dataset.json`, `manifest.jsonl`, `images/*.png`: one format for rendered
and flown collections.

Written by `sim_world.collection.collect` (rendered in the simulator) and `controller.collection`
(flown through the Vehicle interface: a simulated or a real vehicle), read by perception and the
controller through `load_manifest`. The manifest stores where the target is (centre and bbox in
pixels), the drone's pose, the split and the sector; labels are derived from the offsets with
`controller.planning.actions.label_from_offset`, so ε can change without collecting again.

`dataset.json`'s `source` says which kind of collection wrote it: "rendered" (the default: datasets
written before flown ones existed carry no `source`) or "flown". What only a simulator knows (a row's
`scene_seed`, `scene`, `visible_fraction`, `depth_m`, `offset_m`; `generator_version`, `seed`,
`scene_config` in `dataset.json`) is required of a rendered dataset and optional in a flown one. A
flown row's pixel truth is its label (the target's box tracked from the goal image, checked against
the pose geometry: `label` holds both sources); a row whose sources disagree carries
`label.flagged: true` and is left out by `load_manifest` unless asked for (`dronectl dataset check`
counts it). Held-out rows (`is_held_out`): a rendered dataset's test scene seeds, a flown one's test
time blocks (its `test` and `empty` splits).

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

from drone_inspect_core.vocabulary import colour_name

logger = logging.getLogger(__name__)

GENERATOR_VERSION = "sim_world.collect/2"  # a format id (kept when code moves); 2: floor plane not drawn
DATASET_JSON = "dataset.json"
MANIFEST = "manifest.jsonl"
IMAGES_DIR = "images"

RENDERED, FLOWN = "rendered", "flown"
SOURCES = (RENDERED, FLOWN)
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
_TARGET_FIELDS: dict[str, type | tuple[type, ...]] = {
    "kind": str,
    "attribute": (str, type(None)),  # None: a target with no trim to name (a picture face)
    **_TRUTH_FIELDS,
}
"""Each entry of a row's optional `targets` list."""
SIMULATOR_ROW_FIELDS = ("scene_seed", "visible_fraction", "depth_m", "offset_m", "scene")
"""Row fields only a simulator knows: required of a rendered dataset, optional in a flown one."""
_FLOWN_ROW_FIELDS: dict[str, type | tuple[type, ...]] = {
    "flight": int,
    "block": int,
    "time_s": (int, float),
    "label": dict,
}
"""What a flown row carries besides the common fields: which flight and time block, the vehicle's
clock at the capture, and the label's two sources."""
_META_FIELDS = ("generator_version", "seed", "camera", "scene_config", "counts")
SIMULATOR_META_FIELDS = ("generator_version", "seed", "scene_config")
"""`dataset.json` fields only a simulator knows: required of a rendered dataset, optional in a flown one."""


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
    """Appends manifest rows, one flushed line each (context manager). `append`: go on after the rows an
    earlier (interrupted) collection wrote, instead of starting the file."""

    def __init__(self, out_dir: Path, append: bool = False) -> None:
        self.path = out_dir / MANIFEST
        self._file: TextIO = self.path.open("a" if append else "w", encoding="utf-8")
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
    if not isinstance(row["target_attribute"], str | None):
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
    truth = {k: row[k] for k in _TRUTH_FIELDS if k in row}  # a flown row lacks what only a simulator knows
    return [{"kind": row["target_kind"], "attribute": attribute, **truth}]


def dataset_source(meta: dict[str, Any]) -> str:
    """ "rendered" or "flown": who wrote the dataset (`dataset.json`'s `source`; none: rendered)."""
    return str(meta.get("source", RENDERED))


def _check_row(row: object, where: str, source: str = RENDERED) -> dict[str, Any]:
    if not isinstance(row, dict):
        raise DatasetError(f"{where}: expected a JSON object, got {type(row).__name__}")
    if source == RENDERED:
        _check_fields(row, _ROW_FIELDS, where)
    else:  # what only a simulator knows may be absent; where present it has its type
        fields = {k: t for k, t in _ROW_FIELDS.items() if k not in SIMULATOR_ROW_FIELDS or k in row}
        _check_fields(row, {**fields, **_FLOWN_ROW_FIELDS}, where)
        if not isinstance(row["label"].get("flagged"), bool):
            raise DatasetError(f"{where}: field 'label.flagged' must be true or false")
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


def is_flagged(row: dict[str, Any]) -> bool:
    """A flown row whose two label sources disagreed: kept on disk, never trained or scored on."""
    label = row.get("label")
    return isinstance(label, dict) and bool(label.get("flagged", False))


def is_held_out(row: dict[str, Any], meta: dict[str, Any]) -> bool:
    """Whether a row belongs to the held-out part of its dataset: a rendered row of a test scene seed,
    a flown row of a test time block (split `test` or `empty`)."""
    if dataset_source(meta) == FLOWN:
        return row["split"] in ("test", "empty")
    return row.get("scene_seed") in set(meta.get("test_scene_seeds") or [])


def load_manifest(
    directory: str | Path, check_images: bool = True, include_flagged: bool = False
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Read a dataset folder: (manifest rows in file order, the `dataset.json` contents).

    Raises `DatasetError` naming the file and line for a missing folder, a missing or
    malformed `dataset.json`, a corrupt manifest line or a row whose image is missing.
    An interrupted collection (`"complete": false`) loads with a warning, and a torn
    final line it may have left is skipped. Flagged rows (a flown capture whose label sources
    disagreed) are left out unless `include_flagged`.
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
    source = dataset_source(meta)
    if source not in SOURCES:
        raise DatasetError(f"{meta_path}: field 'source' is {source!r}, expected one of {SOURCES}")
    for name in _META_FIELDS:
        if name not in meta and (source == RENDERED or name not in SIMULATOR_META_FIELDS):
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
        row = _check_row(row, where, source)
        if check_images and not (root / row["image"]).is_file():
            raise DatasetError(f"{where}: image {row['image']!r} is missing")
        rows.append(row)
    if not complete:
        logger.warning("%s: the collection was interrupted; %d rows are usable", root, len(rows))
    if not include_flagged:
        flagged = sum(1 for row in rows if is_flagged(row))
        if flagged:
            logger.info("%s: leaving out %d flagged rows (their label sources disagreed)", root, flagged)
            rows = [row for row in rows if not is_flagged(row)]
    return rows, meta
