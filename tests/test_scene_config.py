"""Scene files: the shipped ones load, and a bad one is refused naming the file and the field."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim_world.scene.config import DEFAULT_SCENE, SceneConfigError, load_scene_config

SCENES_DIR = Path(__file__).resolve().parents[1] / "scenes"


def test_default_yaml_is_the_default_scene() -> None:
    assert load_scene_config(SCENES_DIR / "default.yaml") == DEFAULT_SCENE


@pytest.mark.parametrize("path", sorted(SCENES_DIR.glob("**/*.yaml")), ids=lambda p: p.name)
def test_every_shipped_scene_file_loads(path: Path) -> None:
    config = load_scene_config(path)
    assert config.target.kinds  # at least one kind to draw


def test_a_partial_file_overrides_only_what_it_names(tmp_path: Path) -> None:
    path = tmp_path / "valve_only.yaml"
    path.write_text("target:\n  kinds: valve\n  size_m: [0.3, 0.3]\n")
    config = load_scene_config(path)
    assert config.target.kinds == ("valve",)
    assert config.target.size_m == (0.3, 0.3)
    assert config.target.height_m == DEFAULT_SCENE.target.height_m
    assert config.lighting == DEFAULT_SCENE.lighting


@pytest.mark.parametrize(
    ("text", "field", "reason"),
    [
        ("target:\n  size_m: big\n", "target.size_m", "expected a list"),
        ("target:\n  size_m: [0.5, 0.2]\n", "target.size_m", "min 0.5 > max 0.2"),
        ("target:\n  colour: red\n", "target.colour", "unknown key"),
        ("targets:\n  kinds: [gauge]\n", "targets", "unknown key"),
        ("target:\n  kinds: [gauge, dial]\n", "target.kinds[1]", "known kinds: gauge, valve, switchbox"),
        ("target:\n  kinds: []\n", "target.kinds", "at least 1"),
        ("target:\n  dial_colours: ['#fff']\n", "target.dial_colours[0]", "#rrggbb"),
        ("wall:\n  north_m: far\n", "wall.north_m", "valid number"),
        ("wall:\n  textures: [marble]\n", "wall.textures[0]", "'concrete', 'brick' or 'painted_metal'"),
        ("clutter:\n  distractors: [1.5, 2]\n", "clutter.distractors[0]", "integer"),
        ("clutter:\n  distractors: [-1, 2]\n", "clutter.distractors", "within [0, 10]"),
        ("lighting:\n  ambient: [0.2, 1.5]\n", "lighting.ambient", "within [0, 1]"),
        ("lighting:\n  shadow: sometimes\n", "lighting.shadow", "valid boolean"),
        ("camera_noise_std: [3, 1]\n", "camera_noise_std", "min 3 > max 1"),
        ("target:\n  count: [0, 2]\n", "target.count", "within [1, 4]"),
        ("target:\n  count: [2, 5]\n", "target.count", "within [1, 4]"),
        ("target:\n  count: two\n", "target.count", "expected a list"),
        (
            "target:\n  count: [3, 3]\n  other_kinds: [gauge]\n  bezel_colours: ['#c0392b']\n",
            "target.count",
            "must differ in kind or bezel colour name",
        ),
        ("target:\n  count: [2, 2]\n  twins: true\n  bezel_colours: ['#c0392b']\n", "target.count", "twins"),
        ("target:\n  other_kinds: [dial]\n", "target.other_kinds[0]", "known kinds: gauge, valve, switchbox"),
    ],
)
def test_invalid_field_is_named(tmp_path: Path, text: str, field: str, reason: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(SceneConfigError) as info:
        load_scene_config(path)
    error = info.value
    assert error.field == field
    assert reason in error.reason
    assert str(error).startswith(f"{path}: {field}: ")


def test_several_bad_fields_are_all_reported(tmp_path: Path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("target:\n  size_m: [0.5, 0.2]\nlighting:\n  diffuse: [0, 2]\n")
    expected = r"target\.size_m: min 0\.5 > max 0\.2 \(also lighting\.diffuse: must lie within"
    with pytest.raises(SceneConfigError, match=expected):
        load_scene_config(path)


def test_yaml_syntax_error_names_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("target:\n  kinds: [gauge, valve\nwall:\n  north_m: 3\n")
    with pytest.raises(SceneConfigError) as info:
        load_scene_config(path)
    assert info.value.field is None
    assert str(info.value).startswith(f"{path}: YAML syntax error at line ")


def test_missing_file_is_named(tmp_path: Path) -> None:
    path = tmp_path / "nowhere.yaml"
    with pytest.raises(SceneConfigError, match=r"nowhere\.yaml: no such file"):
        load_scene_config(path)


@pytest.mark.parametrize(("text", "kind"), [("- gauge\n- valve\n", "list"), ("just words\n", "str")])
def test_top_level_must_be_a_mapping(tmp_path: Path, text: str, kind: str) -> None:
    path = tmp_path / "odd.yaml"
    path.write_text(text)
    with pytest.raises(SceneConfigError, match=f"expected a mapping at the top level, got {kind}"):
        load_scene_config(path)


def test_empty_file_is_the_default(tmp_path: Path) -> None:
    path = tmp_path / "empty.yaml"
    path.write_text("# nothing set\n")
    assert load_scene_config(path) == DEFAULT_SCENE


def test_the_wide_training_family_keeps_the_held_out_look_out() -> None:
    """scenes/train_wide.yaml may widen the default family, never into the held-out look's paint or light."""
    root = Path(__file__).resolve().parents[1] / "scenes"
    wide, held = load_scene_config(root / "train_wide.yaml"), load_scene_config(root / "heldout_look.yaml")
    assert not set(wide.wall.colours) & set(held.wall.colours)
    assert not set(wide.floor.colours) & set(held.floor.colours)
    lo, hi = wide.lighting.azimuth_deg
    held_lo, held_hi = held.lighting.azimuth_deg
    assert held_hi < lo or hi < held_lo, (wide.lighting.azimuth_deg, held.lighting.azimuth_deg)
    assert wide.target.bezel_colours == held.target.bezel_colours  # the words name these in both


FACTORS = {"train_light": ("lighting",), "train_paint": ("wall", "floor"), "train_clutter": ("clutter",)}


@pytest.mark.parametrize("name", sorted(FACTORS))
def test_each_look_factor_file_changes_one_factor_of_the_held_out_look(name: str) -> None:
    """scenes/look_factors/*.yaml: the held-out look with exactly its factor taken from train_wide.yaml."""
    held = load_scene_config(SCENES_DIR / "heldout_look.yaml")
    wide = load_scene_config(SCENES_DIR / "train_wide.yaml")
    factor = load_scene_config(SCENES_DIR / "look_factors" / f"{name}.yaml")
    assert sorted(FACTORS) == sorted(p.stem for p in (SCENES_DIR / "look_factors").glob("*.yaml"))
    for part in ("target", "wall", "floor", "clutter", "lighting"):
        expected = wide if part in FACTORS[name] else held
        assert getattr(factor, part) == getattr(expected, part), part
    assert factor != held
