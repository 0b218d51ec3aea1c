"""Procedural faces of the inspection targets and of the look-alike distractors.

Drawn at twice the output size and area-filtered down, so ticks, needles and text are
anti-aliased. Each is a pure function of its arguments (see `textures.py`). Images are
RGB with row 0 at the top; the scene maps them onto the front faces upright.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from sim_world.scene.textures import downsample

RGB = tuple[int, int, int]

GAUGE_SCALES: tuple[tuple[float, float, str], ...] = (
    (10.0, 1.0, "bar"),
    (16.0, 2.0, "bar"),
    (25.0, 5.0, "bar"),
    (6.0, 1.0, "bar"),
    (4.0, 0.5, "MPa"),
    (100.0, 10.0, "psi"),
    (160.0, 20.0, "psi"),
    (250.0, 50.0, "kPa"),
)
"""(full scale, major tick step, unit) of the dials a gauge may carry."""

SWEEP_START_DEG = 225.0
"""Gauge zero, as a math angle (counter-clockwise from the right); full scale is 270° clockwise."""
SWEEP_DEG = 270.0

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_BLACK: RGB = (20, 20, 20)
_WHITE: RGB = (245, 245, 245)


def _polar(cx: float, cy: float, radius: float, angle_deg: float) -> tuple[int, int]:
    """Image point at a math angle (y up) around (cx, cy); cv2 wants integer pixels."""
    a = math.radians(angle_deg)
    return round(cx + radius * math.cos(a)), round(cy - radius * math.sin(a))


def _text_centred(
    image: np.ndarray, text: str, centre: tuple[float, float], scale: float, colour: RGB
) -> None:
    thickness = max(1, round(scale * 2.2))
    (w, h), _ = cv2.getTextSize(text, _FONT, scale, thickness)
    origin = (round(centre[0] - w / 2), round(centre[1] + h / 2))
    cv2.putText(image, text, origin, _FONT, scale, colour, thickness, cv2.LINE_AA)


def _ring(image: np.ndarray, centre: tuple[int, int], r_out: float, r_in: float, rgb: RGB) -> None:
    """A metallic-looking ring: the colour lit from the top-left, darker bottom-right."""
    n = image.shape[0]
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32)
    dx, dy = xx - centre[0], yy - centre[1]
    r = np.hypot(dx, dy)
    light = 1.0 + 0.25 * (-(dx + dy) / np.maximum(r, 1.0)) * np.clip((r - r_in) / max(r_out - r_in, 1), 0, 1)
    mask = (r <= r_out) & (r >= r_in)
    image[mask] = np.clip(np.asarray(rgb, np.float32) * light[mask][:, None], 0, 255).astype(np.uint8)


def gauge_dial(
    dial_rgb: RGB,
    bezel_rgb: RGB,
    fraction: float,
    scale_index: int,
    red_zone: bool,
    red_needle: bool,
    size_px: int = 256,
) -> np.ndarray:
    """A pressure-gauge face: bezel ring, dial, ticks, numbers, unit, red zone, needle.

    `fraction` is the reading as a fraction of full scale; the dial fills the inscribed
    circle of the square image (the corners are bezel colour and never shown).
    """
    n = 2 * size_px
    c = n / 2.0
    centre = (round(c), round(c))
    image = np.empty((n, n, 3), np.uint8)
    image[:] = bezel_rgb
    _ring(image, centre, c, 0.84 * c, bezel_rgb)
    face_r = 0.84 * c
    cv2.circle(image, centre, round(face_r), dial_rgb, -1, cv2.LINE_AA)
    cv2.circle(image, centre, round(face_r), (70, 70, 70), max(1, n // 200), cv2.LINE_AA)

    full_scale, step, unit = GAUGE_SCALES[scale_index % len(GAUGE_SCALES)]
    tick_out = 0.93 * face_r
    if red_zone:
        a0, a1 = SWEEP_START_DEG - 0.8 * SWEEP_DEG, SWEEP_START_DEG - SWEEP_DEG
        axes = (round(0.88 * face_r), round(0.88 * face_r))
        # cv2.ellipse angles run clockwise from +x (image y is down): negate the math angles
        cv2.ellipse(image, centre, axes, 0, -a0, -a1, (200, 30, 30), round(0.09 * face_r), cv2.LINE_AA)
    n_major = round(full_scale / step)
    for k in range(5 * n_major + 1):
        angle = SWEEP_START_DEG - SWEEP_DEG * k / (5 * n_major)
        major = k % 5 == 0
        inner = (0.78 if major else 0.86) * face_r
        width = max(1, round(face_r * (0.025 if major else 0.012)))
        cv2.line(image, _polar(c, c, inner, angle), _polar(c, c, tick_out, angle), _BLACK, width, cv2.LINE_AA)
        if major:
            value = step * k / 5
            label = f"{value:g}"
            _text_centred(image, label, _polar(c, c, 0.6 * face_r, angle), face_r / 200.0, _BLACK)
    _text_centred(image, unit, (c, c + 0.42 * face_r), face_r / 190.0, (60, 60, 60))

    needle_angle = SWEEP_START_DEG - SWEEP_DEG * float(np.clip(fraction, 0.0, 1.0))
    needle_rgb: RGB = (190, 20, 20) if red_needle else _BLACK
    tip = _polar(c, c, 0.82 * face_r, needle_angle)
    left = _polar(c, c, 0.035 * face_r, needle_angle + 90)
    right = _polar(c, c, 0.035 * face_r, needle_angle - 90)
    tail = _polar(c, c, 0.18 * face_r, needle_angle + 180)
    cv2.fillPoly(image, [np.array([tip, left, tail, right], np.int32)], needle_rgb, cv2.LINE_AA)
    cv2.circle(image, centre, round(0.07 * face_r), (40, 40, 40), -1, cv2.LINE_AA)
    return downsample(image, size_px, size_px)


def instrument_dial(accent_rgb: RGB, fraction: float, size_px: int = 128) -> np.ndarray:
    """A distractor: a round thermometer-style dial, dark face and a half-circle white scale.

    Round like a gauge and about as big, but with a different face: the hard negative a
    detector must not take for the target.
    """
    n = 2 * size_px
    c = n / 2.0
    centre = (round(c), round(c))
    image = np.empty((n, n, 3), np.uint8)
    image[:] = (150, 150, 150)
    _ring(image, centre, c, 0.88 * c, (165, 168, 172))
    face_r = 0.88 * c
    cv2.circle(image, centre, round(face_r), (28, 30, 34), -1, cv2.LINE_AA)
    for k in range(11):
        angle = 180.0 - 18.0 * k
        inner = (0.7 if k % 5 == 0 else 0.8) * face_r
        cv2.line(image, _polar(c, c, inner, angle), _polar(c, c, 0.9 * face_r, angle), _WHITE, 3, cv2.LINE_AA)
    _text_centred(image, "TEMP", (c, c + 0.4 * face_r), face_r / 110.0, _WHITE)
    angle = 180.0 - 180.0 * fraction
    cv2.line(image, centre, _polar(c, c, 0.85 * face_r, angle), accent_rgb, max(2, n // 60), cv2.LINE_AA)
    return downsample(image, size_px, size_px)


SWITCHBOX_LABELS = ("PUMP", "MCC", "DB", "FAN", "HVAC", "PANEL", "MOTOR", "LIGHTING")


def switchbox_panel(
    body_rgb: RGB,
    trim_rgb: RGB,
    label_index: int,
    label_number: int,
    switches: tuple[int, ...],
    lights: tuple[int, ...],
    width_px: int = 256,
    height_px: int = 320,
) -> np.ndarray:
    """A switch-box door: frame, label plate, switches (rotary 0 / toggle 1), lamps, warning sticker.

    `switches` gives each switch's style; `lights` each indicator lamp's colour
    (0 green, 1 red, 2 amber).
    """
    w, h = 2 * width_px, 2 * height_px
    image = np.empty((h, w, 3), np.uint8)
    image[:] = body_rgb
    border = round(0.05 * w)
    cv2.rectangle(image, (0, 0), (w - 1, h - 1), trim_rgb, border)
    shadow = tuple(int(v * 0.7) for v in body_rgb)
    cv2.rectangle(image, (border, border), (w - border, h - border), shadow, max(2, w // 120))
    cv2.rectangle(
        image, (w - 2 * border, h // 2 - 3 * border), (w - border - 6, h // 2 + 3 * border), (60, 60, 60), -1
    )

    plate = (round(0.18 * w), round(0.08 * h), round(0.82 * w), round(0.2 * h))
    cv2.rectangle(image, plate[:2], plate[2:], _WHITE, -1)
    cv2.rectangle(image, plate[:2], plate[2:], _BLACK, 2)
    text = f"{SWITCHBOX_LABELS[label_index % len(SWITCHBOX_LABELS)]}-{label_number}"
    _text_centred(image, text, ((plate[0] + plate[2]) / 2, (plate[1] + plate[3]) / 2), w / 260.0, _BLACK)

    row_y = 0.4 * h
    for i, style in enumerate(switches):
        x = w * (i + 1) / (len(switches) + 1)
        if style == 0:  # rotary selector: black knob with a white bar, 0 / I marks
            cv2.circle(image, (round(x), round(row_y)), round(0.08 * w), (25, 25, 25), -1, cv2.LINE_AA)
            cv2.line(
                image, (round(x - 0.05 * w), round(row_y)), (round(x + 0.05 * w), round(row_y)), _WHITE, 6
            )
            _text_centred(image, "0", (x - 0.1 * w, row_y - 0.09 * w), w / 520.0, _BLACK)
            _text_centred(image, "I", (x + 0.1 * w, row_y - 0.09 * w), w / 520.0, _BLACK)
        else:  # toggle: a plate with a lever
            cv2.rectangle(
                image,
                (round(x - 0.04 * w), round(row_y - 0.08 * w)),
                (round(x + 0.04 * w), round(row_y + 0.08 * w)),
                (90, 90, 90),
                -1,
            )
            cv2.rectangle(
                image,
                (round(x - 0.015 * w), round(row_y - 0.07 * w)),
                (round(x + 0.015 * w), round(row_y)),
                (230, 230, 230),
                -1,
            )
    lamp_colours: tuple[RGB, ...] = ((40, 200, 60), (220, 40, 30), (240, 170, 20))
    lamp_names = ("RUN", "FAULT", "READY")
    lamp_y = 0.62 * h
    for i, colour_index in enumerate(lights):
        x = w * (i + 1) / (len(lights) + 1)
        colour = lamp_colours[colour_index % 3]
        cv2.circle(image, (round(x), round(lamp_y)), round(0.055 * w), (50, 50, 50), -1, cv2.LINE_AA)
        cv2.circle(image, (round(x), round(lamp_y)), round(0.042 * w), colour, -1, cv2.LINE_AA)
        cv2.circle(
            image,
            (round(x - 0.012 * w), round(lamp_y - 0.012 * w)),
            round(0.012 * w),
            _WHITE,
            -1,
            cv2.LINE_AA,
        )
        _text_centred(image, lamp_names[colour_index % 3], (x, lamp_y + 0.09 * w), w / 650.0, _BLACK)

    tri_c, tri_r = (0.5 * w, 0.84 * h), 0.09 * w
    triangle = np.array([_polar(*tri_c, tri_r, a) for a in (90, 210, 330)], np.int32)
    cv2.fillPoly(image, [triangle], (250, 200, 0), cv2.LINE_AA)
    cv2.polylines(image, [triangle], True, _BLACK, 4, cv2.LINE_AA)
    _text_centred(image, "!", (tri_c[0], tri_c[1] + 0.015 * w), w / 380.0, _BLACK)
    return downsample(image, width_px, height_px)


SIGNS: tuple[tuple[str, str, RGB, RGB], ...] = (
    ("DANGER", "HIGH VOLTAGE", (200, 25, 30), _WHITE),
    ("CAUTION", "HOT SURFACE", (250, 200, 0), _BLACK),
    ("NOTICE", "EAR PROTECTION", (20, 80, 160), _WHITE),
    ("SAFETY", "EYE WASH", (20, 140, 70), _WHITE),
    ("WARNING", "PRESSURISED", (240, 120, 0), _BLACK),
)
"""(header, body text, header colour, header text colour) of the wall signs."""


def wall_sign(sign_index: int, width_px: int = 256, height_px: int = 128) -> np.ndarray:
    """A rectangular safety sign: coloured header band with a white body and text."""
    header, body, band_rgb, band_text_rgb = SIGNS[sign_index % len(SIGNS)]
    w, h = 2 * width_px, 2 * height_px
    image = np.empty((h, w, 3), np.uint8)
    image[:] = _WHITE
    cv2.rectangle(image, (0, 0), (w - 1, round(0.42 * h)), band_rgb, -1)
    cv2.rectangle(image, (0, 0), (w - 1, h - 1), _BLACK, 4)
    _text_centred(image, header, (w / 2, 0.21 * h), w / 300.0, band_text_rgb)
    _text_centred(image, body, (w / 2, 0.7 * h), w / 560.0, _BLACK)
    return downsample(image, width_px, height_px)


def round_sign(prohibition: bool, size_px: int = 128) -> np.ndarray:
    """A distractor: a round sign, red prohibition ring with a slash or a blue mandatory disc."""
    n = 2 * size_px
    c = n / 2.0
    centre = (round(c), round(c))
    image = np.empty((n, n, 3), np.uint8)
    image[:] = _WHITE
    if prohibition:
        cv2.circle(image, centre, round(0.98 * c), (200, 25, 30), -1, cv2.LINE_AA)
        cv2.circle(image, centre, round(0.78 * c), _WHITE, -1, cv2.LINE_AA)
        cv2.line(
            image,
            _polar(c, c, 0.8 * c, 135),
            _polar(c, c, 0.8 * c, -45),
            (200, 25, 30),
            round(0.16 * c),
            cv2.LINE_AA,
        )
    else:
        cv2.circle(image, centre, round(0.98 * c), (20, 80, 160), -1, cv2.LINE_AA)
        cv2.circle(image, (round(c), round(0.55 * c)), round(0.14 * c), _WHITE, -1, cv2.LINE_AA)
        cv2.rectangle(
            image, (round(0.88 * c), round(0.75 * c)), (round(1.12 * c), round(1.5 * c)), _WHITE, -1
        )
    return downsample(image, size_px, size_px)


def picture_texture(path: Path, width_px: int, height_px: int) -> np.ndarray:
    """A user's picture (a kind's face) as an RGB texture of the panel's shape (stretched to it)."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"{path}: not a readable image")
    return cv2.cvtColor(
        cv2.resize(bgr, (width_px, height_px), interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2RGB
    )
