"""`dronectl collect`: render the paper's dataset in the simulated world (protocol in `plan`).

The plan is split by scene; each scene's images are rendered by one worker process
(one PyBullet client, the scene built once), which writes the PNGs itself and hands
back the manifest rows. The main process writes rows in plan order as chunks
finish, flushing each, so the output is byte-identical for any number of workers
and an interrupted run leaves a readable dataset (see `dataset.py`).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from drone_inspect_core.dataset import (
    DATASET_JSON,
    GENERATOR_VERSION,
    IMAGES_DIR,
    ManifestWriter,
    load_manifest,
    prepare_output_dir,
    write_json_atomic,
)
from drone_inspect_core.frames import enu_to_ned, yaw_enu_to_ned_rad
from drone_inspect_core.parallel import task_executor
from sim_world.collection.plan import (
    CollectConfig,
    CollectionPlan,
    ImageSpec,
    View,
    drone_pose_for_view,
    plan_collection,
    plan_held_out,
    sample_empty_view,
    sample_view,
    sector_of_offset,
)
from sim_world.rendering.camera import ForwardCamera
from sim_world.scene.target_truth import TargetTruth
from sim_world.world import World, WorldConfig

__all__ = ["CollectConfig", "CollectResult", "collect", "load_manifest", "plan_held_out", "render_scenes"]

logger = logging.getLogger(__name__)

PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
"""Filters + Huffman coding without LZ77 matching: on these (noisy) renders ~2.5x quicker than
zlib's level 1 and no larger (LZ77 finds few repeats in sensor noise)."""
_EMPTY_TRIES = 20
SCENES_PER_JOB = 3
"""Scenes per worker task: enough to reuse a PyBullet client, few enough to keep workers balanced."""


@dataclass(frozen=True)
class CollectResult:
    out_dir: Path
    counts: dict[str, int]
    seconds: float

    @property
    def images_per_s(self) -> float:
        return sum(self.counts.values()) / self.seconds if self.seconds > 0 else math.inf


def _target_half_m(world: World) -> tuple[float, float]:
    """Half width (east) and half height of the target's face, from its outline."""
    outline = np.asarray(world.scene.target_corners_enu_m, dtype=float)
    extent = outline.max(axis=0) - outline.min(axis=0)
    return float(extent[0]) / 2.0, float(extent[2]) / 2.0


def _offset_m(world: World, position_enu: np.ndarray, yaw_enu: float) -> dict[str, float]:
    """The drone's pose relative to the centred pose in front of the target (wall-aligned)."""
    target = np.asarray(world.scene.target_centre_enu_m, dtype=float)
    return {
        "right_m": round(float(position_enu[0] - target[0]), 4),
        "up_m": round(float(position_enu[2] - target[2]), 4),
        "distance_m": round(float(target[1] - position_enu[1]), 4),
        "yaw_deg": round(math.degrees(yaw_enu_to_ned_rad(yaw_enu)), 4),
    }


def _side_reach_m(world: World) -> tuple[float, float] | None:
    """How far the targets' faces reach west and east of the named target's centre (None: one target)."""
    if len(world.scene.targets) == 1:
        return None
    centre_east = float(world.scene.target_centre_enu_m[0])
    east = np.concatenate([np.asarray(t.corners_enu_m, dtype=float)[:, 0] for t in world.scene.targets])
    return centre_east - float(east.min()), float(east.max()) - centre_east


def _place(world: World, cfg: CollectConfig, spec: ImageSpec, rng: np.random.Generator) -> View:
    """Teleport the drone to a sampled pose for this image (redrawing poses the altitude limits refuse).

    Poses are relative to the named target; an empty view puts every target beside the image.
    """
    half_m = _target_half_m(world)
    reach_m = _side_reach_m(world)
    target = np.asarray(world.scene.target_centre_enu_m, dtype=float)
    for _ in range(100):
        if spec.split == "empty":
            view = sample_empty_view(rng, cfg, half_m, reach_m)
        else:
            view = sample_view(spec, rng, cfg, half_m)
        position, yaw = drone_pose_for_view(world.camera, target, view)
        if cfg.altitude_m[0] <= position[2] <= cfg.altitude_m[1]:
            world.teleport(position, yaw)
            return view
    raise RuntimeError(
        f"{spec.image_id}: no pose within altitude {cfg.altitude_m} m for sector {spec.sector}"
    )


def _truth_fields(truth: TargetTruth) -> dict[str, Any]:
    """A target's truth as manifest fields (the named one's in the row itself; every `targets` entry)."""
    du, dv = truth.offset_px
    return {
        "centre_px": [round(truth.centre_px[0], 3), round(truth.centre_px[1], 3)],
        "offset_px": [round(du, 3), round(dv, 3)],
        "bbox_px": None if truth.bbox_px is None else [round(x, 3) for x in truth.bbox_px],
        "in_view": truth.in_view,
        "fully_in_view": truth.fully_in_view,
        "visible_fraction": round(truth.visible_fraction, 4),
        "depth_m": round(truth.depth_m, 4),
    }


def _render_one(
    world: World, cfg: CollectConfig, spec: ImageSpec, scene_params: dict[str, Any]
) -> dict[str, Any]:
    rng = np.random.default_rng([cfg.seed, spec.index])
    noise_rng = np.random.default_rng([cfg.seed, spec.index, 1])
    scene = world.scene
    for _ in range(_EMPTY_TRIES):
        _place(world, cfg, spec, rng)
        render = world.render(with_seg=True, rng=noise_rng)
        truths = world.targets_truth(render)
        if spec.split != "empty" or all(t.bbox_px is None and t.mask_px == 0 for t in truths):
            break
    else:
        raise RuntimeError(
            f"{spec.image_id}: no view without any of the {len(truths)} target(s) in {_EMPTY_TRIES} tries"
        )
    truth = truths[scene.named_index]
    du, dv = truth.offset_px
    if spec.split != "empty" and sector_of_offset(du, dv, cfg.epsilon) != spec.sector:
        raise RuntimeError(  # an internal error: the pose solver and the truth disagree
            f"{spec.image_id}: planned sector {spec.sector}, got offset ({du:.2f}, {dv:.2f})"
        )
    relative = f"{IMAGES_DIR}/{spec.image_id}.png"
    path = cfg.out_dir / relative
    if not cv2.imwrite(str(path), cv2.cvtColor(render.rgb, cv2.COLOR_RGB2BGR), PNG_PARAMS):
        raise OSError(f"{path}: cv2.imwrite failed")
    state = world.state()
    yaw_enu = state.yaw_enu_rad
    return {
        "id": spec.image_id,
        "image": relative,
        "split": spec.split,
        "sector": spec.sector,
        "scene_seed": spec.scene_seed,
        "target_kind": scene.target_kind,
        "target_attribute": scene.target_attribute,
        **_truth_fields(truth),
        "drone": {
            "position_ned_m": [round(float(x), 4) for x in enu_to_ned(state.position_enu_m)],
            "yaw_deg": round(math.degrees(yaw_enu_to_ned_rad(yaw_enu)), 4),
        },
        "offset_m": _offset_m(world, state.position_enu_m, yaw_enu),
        "named": scene.named_index,
        "targets": [
            {"kind": target.kind, "attribute": target.attribute, **_truth_fields(t)}
            for target, t in zip(scene.targets, truths, strict=True)
        ],
        "scene": scene_params,
    }


def render_scenes(job: tuple[CollectConfig, tuple[tuple[ImageSpec, ...], ...]]) -> list[dict[str, Any]]:
    """Render and write the images of a few scenes (runs in a worker process); returns their rows.

    One PyBullet client serves all of them: `World.reset` rebuilds the next scene in
    about half the time of a new world, and gives the same images.
    """
    cfg, chunks = job
    rows: list[dict[str, Any]] = []
    with World(WorldConfig(scene=cfg.scene, camera=cfg.camera), seed=chunks[0][0].scene_seed) as world:
        for specs in chunks:
            if world.seed != specs[0].scene_seed:
                world.reset(specs[0].scene_seed)
            scene_params = world.scene.params()
            rows += [_render_one(world, cfg, spec, scene_params) for spec in specs]
    return rows


def _metadata(
    cfg: CollectConfig, plan: CollectionPlan, counts: dict[str, int], complete: bool
) -> dict[str, Any]:
    k = ForwardCamera(cfg.camera).intrinsics
    planned: dict[str, int] = {}
    for spec in plan.images:
        planned[spec.split] = planned.get(spec.split, 0) + 1
    return {
        "generator_version": GENERATOR_VERSION,
        "seed": cfg.seed,
        "created_by": "dronectl collect",
        "complete": complete,
        "camera": {
            "width": k.width,
            "height": k.height,
            "hfov_deg": cfg.hfov_deg,
            **k.as_dict(),
            "mount": cfg.camera.mount,
        },
        "epsilon_px": cfg.epsilon,
        "sectors": "where the target lies in the image: N = above centre (dv < -eps, |du| <= eps), "
        "E = right (du > eps), ...; 'centre' = within eps on both axes",
        "protocol": {
            "images_per_scene": cfg.images_per_scene,
            "distance_m": list(cfg.distance_m),
            "yaw_deg": [-cfg.yaw_deg, cfg.yaw_deg],
            "edge_fraction": cfg.edge_fraction,
            "altitude_m": list(cfg.altitude_m),
            "targets": list(cfg.scene.target.count),
            "twins": cfg.scene.target.twins,
            "relative_to": "the named target (row field 'named', an index into 'targets')",
        },
        "scene_file": cfg.scene_file,
        "scene_config": cfg.scene.model_dump(mode="json"),
        "counts": counts,
        "planned_counts": planned,
        "train_scene_seeds": list(plan.train_scene_seeds),
        "test_scene_seeds": list(plan.test_scene_seeds),
    }


class CollectionTaskError(RuntimeError):
    """Some chunks of the collection failed on their workers; the others were written."""


def collect(
    cfg: CollectConfig, progress: bool = True, ray: str | None = None, plan: CollectionPlan | None = None
) -> CollectResult:
    """Run the collection into `cfg.out_dir` (which must not hold a dataset yet).

    `plan`: the images to render (default `plan_collection(cfg)`; `plan_held_out` for a sample
    of test and empty images on chosen scene seeds).

    `ray` (`drone_inspect_core.parallel`): render the chunks of scenes on Ray ("local" or a cluster's address)
    instead of local processes. A chunk that fails (a crashed worker) is named by its scene seeds
    after the others have been written; the dataset then holds the others and is marked incomplete.
    """
    out_dir = Path(cfg.out_dir)
    prepare_output_dir(out_dir)
    plan = plan_collection(cfg) if plan is None else plan
    counts = {"goal": 0, "train": 0, "test": 0, "empty": 0}
    write_json_atomic(out_dir / DATASET_JSON, _metadata(cfg, plan, counts, complete=False))
    chunks = plan.chunks()
    jobs = [(cfg, tuple(chunks[i : i + SCENES_PER_JOB])) for i in range(0, len(chunks), SCENES_PER_JOB)]
    workers = min(cfg.workers, len(jobs))
    logger.info(
        "collecting %d images from %d scenes into %s with %d worker(s)%s",
        len(plan.images),
        len(chunks),
        out_dir,
        workers,
        " on Ray" if ray else "",
    )
    start = time.perf_counter()
    complete = False
    failed: list[str] = []
    bar = tqdm(total=len(plan.images), unit="img", desc="collect", disable=not progress)
    try:
        with task_executor(workers, ray) as pool, ManifestWriter(out_dir) as manifest:
            futures = [pool.submit(render_scenes, job) for job in jobs] if pool is not None else None
            for index, job in enumerate(jobs):
                try:
                    rows = futures[index].result() if futures is not None else render_scenes(job)
                except Exception as exc:
                    if futures is None:
                        raise
                    seeds = sorted({specs[0].scene_seed for specs in job[1]})
                    failed.append(f"scene seeds {seeds}: {type(exc).__name__}: {exc}")
                    logger.error("collection chunk with scene seeds %s failed: %s", seeds, exc)
                    continue
                manifest.write(rows)
                for row in rows:
                    counts[row["split"]] += 1
                bar.update(len(rows))
        if failed:
            raise CollectionTaskError(
                f"{len(failed)} of {len(jobs)} chunks failed; the others are written (marked incomplete): "
                + "; ".join(failed)
            )
        complete = True
    except BaseException:
        logger.error(
            "collection stopped after %d of %d images; %s holds a readable dataset of those "
            "(marked incomplete)",
            sum(counts.values()),
            len(plan.images),
            out_dir,
        )
        raise
    finally:
        bar.close()
        write_json_atomic(out_dir / DATASET_JSON, _metadata(cfg, plan, counts, complete=complete))
    return CollectResult(out_dir, counts, time.perf_counter() - start)
