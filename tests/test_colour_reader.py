"""The learned trim-colour reader (`perception.colour_model`), its training (`perception.training.colour`,
`dronectl train-colour`) and how the detector uses it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from dronectl.collect_cmd import main as collect_main
from dronectl.train_colour_cmd import main as train_colour_main

from drone_inspect_core.vocabulary import shipped_vocabulary
from perception import colour_model
from perception.attributes import read_colour
from perception.colour_model import ColourNet, ColourNetConfig, ColourReader, colour_crop, save_checkpoint
from perception.errors import ColourCheckpointError, DetectorCheckpointError
from perception.evaluation.streamed import as_streamed
from perception.image_detector import SHIPPED_DIR as DETECTOR_DIR
from perception.image_detector import ImageDetector
from perception.training.colour import ColourSamples, TrainColourConfig, crop_u8, train_on_samples

COLOURS = shipped_vocabulary().colour_names
KIND_NAMES = shipped_vocabulary().kind_names
SMALL_NET = ColourNetConfig(crop_px=24, widths=(16, 16, 32, 32), hidden=32)


def test_a_crop_is_the_grown_box_with_a_channel_saying_what_lies_in_the_frame() -> None:
    image = np.arange(20 * 20 * 3, dtype=np.uint8).reshape(20, 20, 3)
    inside = colour_crop(image, (4.0, 6.0, 12.0, 14.0), 8, 1.0)  # an 8 px box, not resized
    assert np.allclose(inside[..., :3], image[6:14, 4:12] / 255.0)
    assert (inside[..., 3] == 1.0).all()
    cut = colour_crop(image, (-4.0, 2.0, 4.0, 10.0), 8, 1.0)  # half of it left of the frame
    assert (cut[:, :4] == 0.0).all() and (cut[:, 4:, 3] == 1.0).all()
    assert np.allclose(cut[:, 4:, :3], image[2:10, 0:4] / 255.0)
    grown = colour_crop(image, (8.0, 8.0, 12.0, 12.0), 8, 2.0)  # 4 px box grown to 8 px: 6..14
    assert np.allclose(grown[..., :3], image[6:14, 6:14] / 255.0)


def synthetic_trims(n: int, seed: int, size: int = 48) -> tuple[list[np.ndarray], list[int], list[int]]:
    """Rings (kind 0) and frames (kind 2) of each palette colour, 1–3 px wide, on random walls, with a
    white dial or a door inside, shaded, some as a stream sends them."""
    rng = np.random.default_rng(seed)
    palette = shipped_vocabulary().colours
    images, kinds, colours = [], [], []
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    for i in range(n):
        colour = int(rng.integers(len(COLOURS)))
        shade = rng.uniform(0.7, 1.05)
        trim = np.clip(np.array(palette[COLOURS[colour]].rgb) * shade, 0, 255)
        image = np.empty((size, size, 3), np.float32)
        image[:] = rng.uniform(40, 220, 3)
        half, width = rng.uniform(8, 14), rng.uniform(1.0, 3.0)
        if i % 2 == 0:
            r = np.hypot(xx - size / 2, yy - size / 2)
            image[r < half] = trim
            image[r < half - width] = (240, 238, 230)
            kind = 0
        else:
            d = np.maximum(abs(xx - size / 2), abs(yy - size / 2) * 0.8)
            image[d < half] = trim
            image[d < half - width] = rng.uniform(60, 200, 3)
            kind = 2
        image = image.astype(np.uint8)
        images.append(as_streamed(image) if i % 3 == 0 else image)
        kinds.append(kind)
        colours.append(colour)
    return images, kinds, colours


def samples_of(
    images: list[np.ndarray], kinds: list[int], colours: list[int], net: ColourNetConfig
) -> ColourSamples:
    size = images[0].shape[0]
    box = (size / 2 - 14.0, size / 2 - 14.0, size / 2 + 14.0, size / 2 + 14.0)
    crops = np.stack(
        [crop_u8(image, box, KIND_NAMES[kind], net) for image, kind in zip(images, kinds, strict=True)]
    )
    return ColourSamples(crops, np.array(kinds), np.array(colours), np.arange(len(images)))


def test_training_learns_trim_colours_on_synthetic_targets(tmp_path: Path) -> None:
    torch.set_num_threads(2)
    train = samples_of(*synthetic_trims(1200, seed=0), SMALL_NET)
    held = samples_of(*synthetic_trims(200, seed=1), SMALL_NET)
    config = TrainColourConfig(
        data_dirs=(tmp_path,), out_dir=tmp_path / "run", epochs=20, batch_size=32, net=SMALL_NET
    )
    model, history, best = train_on_samples(config, train, held)
    assert len(history) == 20 and history[best]["val_accuracy"] == max(h["val_accuracy"] for h in history)
    crops = torch.from_numpy(held.crops).permute(0, 3, 1, 2).float() / 255.0
    with torch.no_grad():
        accuracy = float(
            (model(crops, torch.from_numpy(held.kinds)).argmax(1).numpy() == held.colours).mean()
        )
    untrained = ColourNet(SMALL_NET).eval()
    with torch.no_grad():
        before = float(
            (untrained(crops, torch.from_numpy(held.kinds)).argmax(1).numpy() == held.colours).mean()
        )
    assert accuracy >= 0.85, (accuracy, before)  # measured 0.94; five colours: chance is 0.2
    assert before < 0.5


def shipped_reader_with(kinds: tuple[str, ...]) -> ColourReader:
    return ColourReader(ColourNet(ColourNetConfig(kinds=kinds)))


def test_a_kind_the_network_was_not_trained_on_is_read_by_the_rule_reader() -> None:
    yy, xx = np.mgrid[0:64, 0:64]
    r = np.hypot(xx + 0.5 - 32, yy + 0.5 - 32)
    image = np.full((64, 64, 3), (120, 120, 118), np.uint8)
    image[r < 14] = shipped_vocabulary().colours["blue"].rgb
    image[r < 11] = (245, 242, 235)
    box = (18.0, 18.0, 46.0, 46.0)
    reader = shipped_reader_with(("gauge",))
    learned, own, nowhere = reader.read_all(
        image, [(box, "gauge"), (box, "flange"), ((80.0, 80.0, 90.0, 90.0), "gauge")]
    )
    assert own == read_colour(image, box, "flange") and own is not None and own.name == "blue"
    assert learned is not None and learned.name in COLOURS and 0.0 <= learned.doubt < 1.0
    assert nowhere is None  # no pixel of that box lies in the frame
    assert not reader.knows("flange") and reader.knows("gauge")


def test_a_bad_colour_checkpoint_is_refused_with_a_message_naming_the_file(tmp_path: Path) -> None:
    good = tmp_path / "good"
    save_checkpoint(good, ColourNet(SMALL_NET))
    assert ColourReader.load(good).config == SMALL_NET

    def broken(name: str) -> Path:
        folder = tmp_path / name
        shutil.copytree(good, folder)
        return folder

    cases = {}
    (cases.setdefault("no config", broken("a")) / "config.json").unlink()
    (cases.setdefault("not json", broken("b")) / "config.json").write_text("{oops")
    folder = cases.setdefault("another format", broken("c"))
    payload = json.loads((folder / "config.json").read_text())
    (folder / "config.json").write_text(json.dumps({**payload, "format": "drone-inspect/detector/1"}))
    folder = cases.setdefault("unknown colour", broken("d"))
    payload["colour"]["colours"] = [*COLOURS[:-1], "mauve"]
    (folder / "config.json").write_text(json.dumps(payload))
    (cases.setdefault("corrupt weights", broken("e")) / "model.safetensors").write_bytes(b"\x00" * 40)
    folder = cases.setdefault("NaN weights", broken("f"))
    nan = ColourNet(SMALL_NET)
    with torch.no_grad():
        nan.head[0].weight[0, 0] = float("nan")
    save_checkpoint(folder, nan)
    folder = cases.setdefault("another size", broken("g"))
    save_checkpoint(folder, ColourNet(ColourNetConfig()))
    (folder / "config.json").write_text((good / "config.json").read_text())
    for why, folder in cases.items():
        with pytest.raises(ColourCheckpointError) as caught:
            ColourReader.load(folder)
        assert str(folder) in str(caught.value), why
        assert isinstance(caught.value, DetectorCheckpointError)  # what handles a detector's error handles it


@pytest.fixture(scope="module")
def tiny_three_target_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("colour") / "three"
    small = ["--n-goal", "2", "--n-per-sector", "1", "--n-test", "3", "--n-empty", "1", "--size", "96"]
    small += ["--images-per-scene", "8", "--workers", "1", "--no-progress"]
    assert collect_main(["--out", str(out), "--seed", "5", "--targets", "3", *small]) == 0
    return out


def test_train_colour_writes_a_run_a_detector_reads_colours_with(
    tiny_three_target_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    args = ["--data", str(tiny_three_target_dataset), "--out", str(run), "--epochs", "1", "--crop", "24"]
    assert train_colour_main([*args, "--threads", "1"]) == 0
    out = capsys.readouterr().out
    assert "held-out targets read right, learned: lossless" in out and "rules: lossless" in out
    metrics = json.loads((run / "metrics.json").read_text())
    test = metrics["test"]
    assert test["targets"] > 0
    for reader in ("learned", "rules"):
        for encoding in ("lossless", "stream"):
            assert test[reader][encoding]["of"] == test["targets"]
    assert ColourReader.load(run).config.crop_px == 24
    # A second run into the same folder is refused, and what it holds is kept.
    weights = (run / "model.safetensors").read_bytes()
    assert train_colour_main([*args, "--threads", "1"]) == 1
    assert "dronectl train-colour:" in capsys.readouterr().err
    assert (run / "model.safetensors").read_bytes() == weights
    # A detector run folder with a `colour/` folder reads colours with it; one without, with the shipped one.
    own = tmp_path / "detector"
    shutil.copytree(DETECTOR_DIR, own)
    assert ImageDetector.load(own, backend="torch").colour_reader.config == ColourReader.shipped().config
    shutil.copytree(run, own / "colour")
    reader = ImageDetector.load(own, backend="torch").colour_reader
    assert reader is not None and reader.config.crop_px == 24


def test_train_colour_refuses_a_dataset_without_colours_it_can_learn(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert train_colour_main(["--data", str(tmp_path / "nowhere"), "--out", str(tmp_path / "run")]) == 1
    assert "dronectl train-colour:" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_the_shipped_reader_is_a_small_network_of_the_shipped_vocabulary() -> None:
    reader = ColourReader.shipped()
    assert reader.config.colours == COLOURS and set(reader.config.kinds) == set(
        shipped_vocabulary().kind_names
    )
    assert sum(p.numel() for p in reader.model.parameters()) < 200_000
    assert colour_model.SHIPPED_DIR.is_dir()


def test_a_box_as_large_as_the_frame_or_larger_is_read_with_bounded_memory() -> None:
    """A 1920×1080 frame with a box filling it: the crop is taken from the frame shrunk first (the same
    picture as cropping it whole, at the crop's size); a box thousands of frames across is not read."""
    image = np.zeros((1080, 1920, 3), np.uint8)
    image[:, :960] = (200, 30, 30)
    big = colour_crop(image, (0.0, 0.0, 1920.0, 1080.0), 40, 1.4)
    assert big.shape == (40, 40, 4)
    assert big[20, 10, 0] > 0.7 and big[20, 30, 0] < 0.05  # left half red, right half black, kept
    assert big[0, 20, 3] == 0.0 and big[20, 20, 3] == 1.0  # the frame's edge inside the grown crop
    reader = shipped_reader_with(("gauge",))
    huge = (-1e7, -1e7, 1e7, 1e7)
    read, nan = reader.read_all(image, [(huge, "gauge"), ((np.nan, 0.0, 10.0, 10.0), "gauge")])
    assert read is None and nan is None
    whole = reader.read_all(image, [((0.0, 0.0, 1920.0, 1080.0), "gauge")])[0]
    assert whole is not None and whole.name in COLOURS
