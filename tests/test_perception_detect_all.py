"""Every target in a frame: `ImageDetector.detect_all` (kinds, NMS, attributes) on rendered scenes."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from drone_inspect_core.vocabulary import colour_name, shipped_vocabulary
from perception import attributes
from perception.attributes import read_attribute
from perception.detector_model import CentreNet, DetectorConfig
from perception.image_detector import ImageDetector
from sim_world.world import World

SEEDS = range(200, 216)  # scenes never used to tune the attribute reader's bands


@pytest.fixture(scope="module")
def detector() -> ImageDetector:
    torch.set_num_threads(1)
    return ImageDetector.shipped()


def centred_render(seed: int, distance_m: float = 2.0) -> tuple[np.ndarray, str, str]:
    """(rgb, kind, trim colour name) of scene `seed` seen head-on with its target in the middle."""
    with World(seed=seed) as world:
        world.teleport(*world.scene.pose_for_offset(0.0, 0.0, distance_m, 0.0))
        rgb = world.render(with_seg=False).rgb
        return rgb, world.scene.target_kind, colour_name(world.scene.sampled.target.bezel_colour)


@pytest.fixture(scope="module")
def renders() -> dict[int, tuple[np.ndarray, str, str]]:
    return {seed: centred_render(seed, 1.6 + 0.1 * (seed % 10)) for seed in SEEDS}


def test_detect_all_finds_the_single_target_with_its_kind_and_agrees_with_detect(
    detector: ImageDetector, renders: dict[int, tuple[np.ndarray, str, str]]
) -> None:
    for rgb, kind, _ in renders.values():
        found = detector.detect_all(rgb)
        strongest = detector.detect(rgb)
        assert len(found) == 1, found  # one object: no second peak, no second kind on it
        assert found[0].kind == kind
        assert strongest is not None and strongest.attribute is None  # detect() reads no attribute
        assert found[0].centre_px == strongest.centre_px and found[0].confidence == strongest.confidence
        assert found[0].bbox_px == strongest.bbox_px


def test_attribute_reader_names_the_trim_colour(
    detector: ImageDetector, renders: dict[int, tuple[np.ndarray, str, str]]
) -> None:
    found = [detector.detect_all(rgb)[0] for rgb, _, _ in renders.values()]
    right = sum(d.attribute == colour for d, (_, _, colour) in zip(found, renders.values(), strict=True))
    assert all(d.attribute_doubt is not None and d.attribute_doubt >= 0.0 for d in found)
    assert len({c for _, _, c in renders.values()}) >= 4  # the scenes show most trim colours
    assert right >= len(renders) - 2, right  # measured 95 of 100 on held-out scenes


def test_two_renders_side_by_side_give_two_detections_of_their_kinds(detector: ImageDetector) -> None:
    kinds: dict[str, tuple[np.ndarray, str]] = {}
    for seed in range(200, 260):
        rgb, kind, colour = centred_render(seed)
        kinds.setdefault(kind, (rgb, colour))
        if len(kinds) == 3:
            break
    (left_rgb, left_colour), (right_rgb, right_colour) = kinds["valve"], kinds["gauge"]
    image = np.ascontiguousarray(np.concatenate([left_rgb[:, 56:168], right_rgb[:, 56:168]], axis=1))
    found = detector.detect_all(image)
    assert len(found) == 2, found
    by_kind = {d.kind: d for d in found}
    assert set(by_kind) == {"valve", "gauge"}
    assert by_kind["valve"].centre_px[0] == pytest.approx(56, abs=4)
    assert by_kind["gauge"].centre_px[0] == pytest.approx(168, abs=4)
    assert by_kind["valve"].attribute == left_colour and by_kind["gauge"].attribute == right_colour
    assert found[0].confidence >= found[1].confidence
    batch = detector.detect_all_batch([image, left_rgb])
    assert [(d.kind, d.attribute) for d in batch[0]] == [(d.kind, d.attribute) for d in found]
    assert batch[0][0].centre_px == pytest.approx(found[0].centre_px, abs=1e-3)  # batched float sums differ
    assert [d.kind for d in batch[1]] == ["valve"]


def test_read_attribute_on_synthetic_trim() -> None:
    """A ring of each palette colour on a brick-red wall with a white dial; a frame on a grey wall."""
    yy, xx = np.mgrid[0:64, 0:64]
    r = np.hypot(xx + 0.5 - 32, yy + 0.5 - 32)
    for name, rgb in ((c.name, c.rgb) for c in shipped_vocabulary().colours.values()):
        image = np.empty((64, 64, 3), np.uint8)
        image[:] = (150, 70, 50)
        image[r < 14] = rgb
        image[r < 11] = (245, 242, 235)
        assert read_attribute(image, (18.0, 18.0, 46.0, 46.0), "gauge") == name
        box = np.empty((64, 64, 3), np.uint8)
        box[:] = (120, 120, 118)
        box[16:48, 20:44] = rgb
        box[18:46, 22:42] = (240, 238, 230)
        assert read_attribute(box, (20.0, 16.0, 44.0, 48.0), "switchbox") == name
    assert read_attribute(np.zeros((8, 8, 3), np.uint8), (3.0, 3.0, 3.5, 3.5), "gauge") is None


def test_a_colour_read_says_how_well_it_fits() -> None:
    """A ring of the palette's red and a washed-out pinkish-grey ring both read red; the true red fits
    red more closely (the rule reader's doubt, its residual, is lower), which is what tells twins read
    alike apart."""
    yy, xx = np.mgrid[0:64, 0:64]
    r = np.hypot(xx + 0.5 - 32, yy + 0.5 - 32)

    def ring(rgb: tuple[int, int, int]) -> attributes.ColourRead | None:
        image = np.full((64, 64, 3), (120, 120, 118), np.uint8)
        image[r < 14] = rgb
        image[r < 11] = (245, 242, 235)
        return attributes.read_colour(image, (18.0, 18.0, 46.0, 46.0), "valve")

    red, washed = ring(shipped_vocabulary().colours["red"].rgb), ring((170, 100, 90))
    assert red is not None and washed is not None
    assert red.name == washed.name == "red"
    assert red.doubt < washed.doubt / 2
    assert attributes.read_colour(np.zeros((8, 8, 3), np.uint8), (3.0, 3.0, 3.5, 3.5), "gauge") is None


def test_a_ring_cut_by_the_images_edge_is_read_from_its_whole_box() -> None:
    """A gauge whose left third lies beyond the image: the detector's box ends at the edge, so the box's
    own annulus falls inside the white dial (read grey); grown past the edge to the ring's uncut height,
    it finds the bezel. Cut on two sides, the box is used as it is."""
    yy, xx = np.mgrid[0:64, 0:64]
    r = np.hypot(xx + 0.5 - 6, yy + 0.5 - 32)  # centre 6 px from the left edge, radius 14
    for colour in shipped_vocabulary().colours.values():
        image = np.empty((64, 64, 3), np.uint8)
        image[:] = (150, 70, 50)
        image[r < 14] = colour.rgb
        image[r < 11] = (245, 242, 235)
        assert read_attribute(image, (0.0, 18.0, 20.0, 46.0), "gauge") == colour.name, colour.name
        assert read_attribute(image, (0.0, 18.0, 20.0, 46.0), "valve") == colour.name, colour.name
    cornered = (0.0, 0.0, 20.0, 10.0)  # cut by two edges: nothing to grow it from
    assert attributes._beyond_the_edge(cornered, 64, 64) == cornered
    assert attributes._beyond_the_edge((10.0, 54.0, 38.0, 64.0), 64, 64) == (
        10.0,
        54.0,
        38.0,
        82.0,
    )  # past the bottom
    assert attributes._beyond_the_edge((10.0, 20.0, 38.0, 40.0), 64, 64) == (10.0, 20.0, 38.0, 40.0)


def test_a_small_gauges_saturated_bezel_is_not_outvoted_by_its_dial() -> None:
    """A gauge 17 px across with a 1 px bezel, its white dial and black ticks filling most of the band, on
    a blue-grey wall (as the twins set's misread blue gauges): the dial's pixels are best explained by
    grey, and their median read the blue bezel grey. A saturated colour that closely explains enough of
    the band wins; a grey or black bezel is never read as a saturated colour."""
    import cv2

    def small_gauge(rgb: tuple[int, int, int], seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        wall = np.array((81, 99, 115), np.float32) + rng.normal(0, 4, (48, 48, 3))
        image = np.clip(wall, 0, 255).astype(np.uint8)
        cv2.circle(image, (24, 24), 8, tuple(int(v) for v in rgb), -1, cv2.LINE_AA)
        cv2.circle(image, (24, 24), 7, (214, 207, 200), -1, cv2.LINE_AA)
        for angle in np.linspace(0, 2 * np.pi, 12, endpoint=False):
            image[int(24 + 6 * np.sin(angle)), int(24 + 6 * np.cos(angle))] = (20, 20, 20)
        return image

    for colour in shipped_vocabulary().colours.values():
        reads = {
            read_attribute(small_gauge(colour.rgb, s), (15.0, 15.0, 33.5, 33.5), "gauge") for s in range(5)
        }
        if colour.name in ("red", "blue", "yellow"):
            assert reads == {colour.name}, (colour.name, reads)
        else:
            assert reads <= {"black", "grey"}, (colour.name, reads)


def test_a_switch_box_read_around_a_misplaced_box_is_snapped_to_its_door_first(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A 1 px frame, a box 2-3 px off it (as a detector's often is): the frame is found from the door.
    Without the snap the band holds the wall and the door, and most colours read as something else."""
    import perception.attributes as attributes
    from perception.attributes import _door_box

    boxes = []
    for name, rgb in ((c.name, c.rgb) for c in shipped_vocabulary().colours.values()):
        box = np.empty((80, 80, 3), np.uint8)
        box[:] = (128, 118, 110)  # a wall
        box[20:61, 24:55] = rgb  # the frame: rows 20 and 60, columns 24 and 54
        box[21:60, 25:54] = (236, 236, 232)  # the door
        box[28:31, 30:36] = (20, 20, 20)  # a label on it
        off = (27.0, 17.0, 58.0, 58.0)  # 3 px right, 3 px high, 2 px short at the bottom
        assert _door_box(box, off) == pytest.approx((24.0, 20.0, 55.0, 61.0))  # the door grown by 1 px
        assert read_attribute(box, off, "switchbox") == name
        plain = np.full((80, 80, 3), 128, np.uint8)  # nothing like a door: the box is kept
        assert _door_box(plain, off) is None
        boxes.append((box, off, name))
    monkeypatch.setattr(attributes, "_door_box", lambda image, bbox: None)
    assert sum(read_attribute(box, off, "switchbox") != name for box, off, name in boxes) >= 2


def test_decoding_keeps_each_local_peak_once_and_drops_another_kind_on_the_same_object() -> None:
    """A hand-made head output: a gauge peak with a weaker valve peak 1 cell away, a switch box elsewhere."""
    detector = ImageDetector(CentreNet(DetectorConfig()), backend="torch")  # the torch network is stubbed
    grid, k = detector.config.grid_size, len(detector.config.kinds)
    out = torch.zeros(1, k + 6, grid, grid)
    out[:, :k] = -8.0  # sigmoid ≈ 0 everywhere
    out[0, 0, 20, 10], out[0, 0, 20, 11] = 3.0, 2.0  # gauge peak and its shoulder (not a local maximum)
    out[0, 1, 21, 11] = 2.5  # valve, one cell off the gauge: inside its box, the same object
    out[0, 2, 40, 45] = 1.0  # switch box, far away
    out[0, 2, 40, 47] = 0.5  # its second peak, inside its box
    out[0, 1, 5, 50] = -1.0  # a valve below the score threshold
    out[0, k + 2 : k + 6] = float(np.log(12.0 / 16.0))  # every box 12 px each way
    detector._model = lambda x: out.expand(x.shape[0], -1, -1, -1)  # the network stubbed by its output
    found = detector.detect_all(np.full((224, 224, 3), 128, np.uint8))
    assert [d.kind for d in found] == ["gauge", "switchbox"]
    assert found[0].centre_px == pytest.approx((40.0, 80.0)) and found[0].confidence == pytest.approx(
        0.9526, abs=1e-4
    )
    assert found[1].centre_px == pytest.approx((180.0, 160.0))
    single = detector.detect(np.full((224, 224, 3), 128, np.uint8))
    assert single is not None and single.centre_px == found[0].centre_px


def test_a_target_cut_by_the_frame_edge_has_its_colour_read_around_its_whole_box(
    detector: ImageDetector, renders: dict[int, tuple[np.ndarray, str, str]]
) -> None:
    # Each scene's centred target moved to 12 px from the left edge (most of them cut by it).
    right = right_if_clipped = 0
    for rgb, kind, colour in renders.values():
        image = np.ascontiguousarray(
            np.concatenate([rgb[:, 100:], np.repeat(rgb[:, -1:], 100, axis=1)], axis=1)
        )
        found = [d for d in detector.detect_all(image) if d.kind == kind]
        assert found  # seen: its centre is in the frame
        right += found[0].attribute == colour
        right_if_clipped += read_attribute(image, found[0].bbox_px, kind) == colour
    # Measured 16 of 16 around the whole box. Around the clipped one 12 of 16 (its rim on the target's
    # face; 4 before a gauge's saturated bezel outvoted its dial: `attributes._saturated_bezel`) until a
    # round target's box cut by the edge was grown past it (`attributes._beyond_the_edge`): 16 of 16.
    assert right >= len(renders) - 2 and right_if_clipped >= len(renders) - 2, (right, right_if_clipped)


@pytest.mark.parametrize("reader", ["learned", "rules"])
def test_switch_box_frames_are_read_through_the_streams_jpeg(detector: ImageDetector, reader: str) -> None:
    """Switch boxes of held-out scenes, 2.0-2.9 m and 2.5-3.4 m away, as the simulated MJPEG stream
    delivers them (4:2:0 JPEG: a 1 px frame keeps its luma, not its chroma). Measured 64 of 68 frames
    read right by the learned reader (63 on the lossless renders), 62 by the rule reader (66 lossless);
    the rule reader that fitted luma and chroma as one (RGB) read 56."""
    from perception.evaluation.streamed import as_streamed

    if reader == "rules":
        detector = ImageDetector.shipped(backend="torch")
        detector.colour_reader = None
    right = n = 0
    for seed in range(200, 300):
        with World(seed=seed) as world:
            if world.scene.target_kind != "switchbox":
                continue
            colour = colour_name(world.scene.sampled.target.bezel_colour)
            for near in (2.0, 2.5):
                world.teleport(*world.scene.pose_for_offset(0.0, 0.0, near + 0.1 * (seed % 10), 0.0))
                found = detector.detect_all(as_streamed(world.render(with_seg=False).rgb))
                n += 1
                right += bool(found) and found[0].attribute == colour
    assert n == 68
    assert right >= 60, right


def test_the_learned_reader_reads_trims_of_a_look_no_training_saw_through_the_stream(
    detector: ImageDetector,
) -> None:
    """One target of each of 60 scenes of the held-out look (`scenes/heldout_look.yaml`: walls, floors
    and light no training used), 2.0-2.9 m away, through the stream's JPEG. Measured: the learned
    reader 54 of 60 right, the rule reader 37 (gauges 21 / 13 of 21, valves 19 / 16 of 20, switch boxes
    14 / 8 of 19)."""
    from pathlib import Path

    from perception.evaluation.streamed import as_streamed
    from sim_world.scene.config import load_scene_config
    from sim_world.world import WorldConfig

    held = WorldConfig(
        scene=load_scene_config(Path(__file__).resolve().parents[1] / "scenes" / "heldout_look.yaml")
    )
    rules = ImageDetector.shipped(backend="torch")
    rules.colour_reader = None
    right = {"learned": 0, "rules": 0}
    for seed in range(400, 460):
        with World(held, seed=seed) as world:
            kind, colour = world.scene.target_kind, colour_name(world.scene.sampled.target.bezel_colour)
            world.teleport(*world.scene.pose_for_offset(0.0, 0.0, 2.0 + 0.1 * (seed % 10), 0.0))
            picture = as_streamed(world.render(with_seg=False).rgb)
        for name, reading in (("learned", detector), ("rules", rules)):
            found = [d for d in reading.detect_all(picture) if d.kind == kind]
            right[name] += bool(found) and found[0].attribute == colour
    assert right["learned"] >= 50, right
    assert right["rules"] <= 45, right  # what the learned reader adds: the test fails with the rule reader
