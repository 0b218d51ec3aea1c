"""Procedural surface textures (wall, floor) and the helpers every texture shares.

Every texture is a pure function of its arguments: the same arguments give the same
pixels on every machine (numpy's PCG64 and OpenCV's drawing are deterministic), so a
scene seed reproduces a scene down to the bytes of its PNG files. Textures are RGB
uint8 arrays; they stay at 256² (TinyRenderer's cost grows with texture size) and tile
seamlessly, because the wall and floor repeat them every metre or two.

The target and distractor faces (gauge dial, switch-box panel, signs) are drawn in
`textures_targets.py`.
"""

from __future__ import annotations

import zlib

import cv2
import numpy as np

TEXTURE_SIZE_PX = 256
TEXTURE_VARIANTS = 4
"""How many different patterns each wall / floor texture kind has (the seed picks one)."""

WALL_TILE_M = {"concrete": 2.0, "brick": 1.2, "painted_metal": 1.6}
"""Metres of wall one texture tile covers, per kind (a brick is ~0.24 m × 0.07 m)."""
FLOOR_TILE_M = {"concrete": 3.0, "tiles": 1.2, "grating": 1.0}


def texture_rng(*key: object) -> np.random.Generator:
    """A generator seeded from a key such as ("brick", 2): stable across runs and platforms."""
    digest = zlib.crc32(repr(key).encode("utf-8"))
    return np.random.default_rng(digest)


def periodic_noise(rng: np.random.Generator, size_px: int, feature_px: float) -> np.ndarray:
    """Smooth noise that tiles seamlessly, zero mean and unit std (size_px × size_px float32).

    White noise low-passed in the Fourier domain is periodic by construction;
    `feature_px` is the rough size of a blob.
    """
    white = rng.standard_normal((size_px, size_px))
    freq = np.fft.fftfreq(size_px)
    fx, fy = np.meshgrid(freq, freq)
    sigma = 1.0 / (2.0 * np.pi * max(feature_px, 0.5))
    smooth = np.real(np.fft.ifft2(np.fft.fft2(white) * np.exp(-(fx**2 + fy**2) / (2.0 * sigma**2))))
    smooth -= smooth.mean()
    std = smooth.std()
    return (smooth / std if std > 0 else smooth).astype(np.float32)


def fractal_noise(rng: np.random.Generator, size_px: int, octaves: tuple[float, ...]) -> np.ndarray:
    """Sum of periodic noise at several feature sizes, each weighted by its size (unit std)."""
    total = sum(periodic_noise(rng, size_px, f) * f for f in octaves)
    return (total / np.std(total)).astype(np.float32)


def shade(rgb: tuple[int, int, int], brightness: np.ndarray) -> np.ndarray:
    """A colour scaled per pixel by `brightness` (≈1), as an HxWx3 uint8 image."""
    colour = np.asarray(rgb, dtype=np.float32)
    return np.clip(brightness[..., None] * colour, 0, 255).astype(np.uint8)


def _concrete(rng: np.random.Generator, rgb: tuple[int, int, int], n: int) -> np.ndarray:
    brightness = 1.0 + 0.07 * fractal_noise(rng, n, (40.0, 10.0, 2.0)) + 0.04 * rng.standard_normal((n, n))
    image = shade(rgb, brightness.astype(np.float32))
    for _ in range(rng.integers(2, 6)):  # pores and small chips
        centre = (int(rng.integers(0, n)), int(rng.integers(0, n)))
        cv2.circle(image, centre, int(rng.integers(1, 3)), tuple(int(c * 0.6) for c in rgb), -1, cv2.LINE_AA)
    return image


def _wall_concrete(rng: np.random.Generator, rgb: tuple[int, int, int], n: int) -> np.ndarray:
    image = _concrete(rng, rgb, n)
    dark = tuple(int(c * 0.55) for c in rgb)
    for x in (n // 4, 3 * n // 4):  # formwork tie holes, on a grid that tiles
        for y in (n // 4, 3 * n // 4):
            cv2.circle(image, (x, y), 3, dark, -1, cv2.LINE_AA)
    image[n - 1, :] = (image[n - 1, :] * 0.8).astype(np.uint8)  # faint panel joints
    image[:, n - 1] = (image[:, n - 1] * 0.8).astype(np.uint8)
    return image


def _wall_brick(rng: np.random.Generator, rgb: tuple[int, int, int], n: int) -> np.ndarray:
    rows, cols = 16, 5  # 1.2 m tile: bricks 0.24 m × 0.075 m (incl. mortar)
    row_h, col_w = n / rows, n / cols
    mortar = np.array([190, 186, 178], dtype=np.float32)
    grain = 1.0 + 0.08 * fractal_noise(rng, n, (6.0, 1.5))
    image = np.empty((n, n, 3), dtype=np.float32)
    image[:] = mortar * (1.0 + 0.05 * grain[..., None] - 0.05)
    joint = max(1, round(n / 110))
    for r in range(rows):
        offset = 0.5 * col_w if r % 2 else 0.0
        y0, y1 = round(r * row_h) + joint, round((r + 1) * row_h)
        for c in range(-1, cols):
            x0, x1 = round(c * col_w + offset) + joint, round((c + 1) * col_w + offset)
            tone = np.asarray(rgb, dtype=np.float32) * rng.uniform(0.8, 1.12)
            for xa, xb in ((max(x0, 0), min(x1, n)), (max(x0 + n, 0), min(x1 + n, n))):  # wrap around
                if xa < xb:
                    image[y0:y1, xa:xb] = tone * grain[y0:y1, xa:xb, None]
    return np.clip(image, 0, 255).astype(np.uint8)


def _wall_painted_metal(rng: np.random.Generator, rgb: tuple[int, int, int], n: int) -> np.ndarray:
    ribs = 8  # trapezoidal cladding ribs, vertical
    x = np.arange(n, dtype=np.float32)
    profile = 1.0 + 0.1 * np.cos(2.0 * np.pi * ribs * x / n)
    brightness = profile[None, :] + 0.02 * fractal_noise(rng, n, (30.0, 3.0))
    image = shade(rgb, brightness)
    rust = (150, 80, 45)
    for _ in range(rng.integers(1, 4)):  # rust streaks below fixings
        x0, y0 = int(rng.integers(0, n)), int(rng.integers(0, n - 40))
        length = int(rng.integers(15, 40))
        cv2.line(image, (x0, y0), (x0, y0 + length), rust, 2, cv2.LINE_AA)
        cv2.circle(image, (x0, y0), 2, (60, 60, 60), -1, cv2.LINE_AA)
    return image


def _floor_tiles(rng: np.random.Generator, rgb: tuple[int, int, int], n: int) -> np.ndarray:
    tiles = 4
    step = n // tiles
    image = np.empty((n, n, 3), dtype=np.uint8)
    grain = 1.0 + 0.03 * fractal_noise(rng, n, (8.0, 2.0))
    for i in range(tiles):
        for j in range(tiles):
            tone = rng.uniform(0.9, 1.08)
            block = grain[i * step : (i + 1) * step, j * step : (j + 1) * step] * tone
            image[i * step : (i + 1) * step, j * step : (j + 1) * step] = shade(rgb, block)
    grout = tuple(int(c * 0.55) for c in rgb)
    for k in range(tiles):
        image[k * step : k * step + 2, :] = grout
        image[:, k * step : k * step + 2] = grout
    return image


def _floor_grating(rng: np.random.Generator, rgb: tuple[int, int, int], n: int) -> np.ndarray:
    image = shade(tuple(int(c * 0.25) for c in rgb), 1.0 + 0.1 * fractal_noise(rng, n, (20.0,)))
    bar = tuple(int(min(255, c * 1.15)) for c in rgb)
    for k in range(0, n, n // 32):  # bearing bars
        cv2.line(image, (k, 0), (k, n - 1), bar, 2)
    for k in range(0, n, n // 8):  # cross bars
        cv2.line(image, (0, k), (n - 1, k), bar, 2)
    return image


_WALLS = {"concrete": _wall_concrete, "brick": _wall_brick, "painted_metal": _wall_painted_metal}
_FLOORS = {"concrete": _concrete, "tiles": _floor_tiles, "grating": _floor_grating}


def wall_texture(
    kind: str, rgb: tuple[int, int, int], variant: int, size_px: int = TEXTURE_SIZE_PX
) -> np.ndarray:
    """A seamless wall texture tile (RGB uint8) covering `WALL_TILE_M[kind]` metres."""
    return _WALLS[kind](texture_rng("wall", kind, variant), rgb, size_px)


def floor_texture(
    kind: str, rgb: tuple[int, int, int], variant: int, size_px: int = TEXTURE_SIZE_PX
) -> np.ndarray:
    """A seamless floor texture tile (RGB uint8) covering `FLOOR_TILE_M[kind]` metres."""
    return _FLOORS[kind](texture_rng("floor", kind, variant), rgb, size_px)


def downsample(image: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """Area-filter an image drawn at a larger size down to (width, height): cheap anti-aliasing."""
    if image.shape[1] == width_px and image.shape[0] == height_px:
        return image
    return cv2.resize(image, (width_px, height_px), interpolation=cv2.INTER_AREA)
