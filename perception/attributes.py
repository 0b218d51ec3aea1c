"""Reading a detected target's attribute: the colour name of its trim, from the pixels of its box.

The trim is a gauge's bezel ring, a valve's handwheel rim and spokes, a switch box's
door frame (`drone_inspect_core.vocabulary`). At 224 px a target is some 20–40 px across, so the trim is
only 1–3 px wide and most of its pixels are blends with what borders it (the wall, the
dial, the door). A plain median of the band's pixels therefore reads the wall or the
door (measured: 36 of 74 switch boxes right); instead each palette colour is tested as
an explanation of the band:

1. the band: an annulus near the rim of a round target's box (`r` in [0.72, 1.05] of
   the half-axes), a frame along the edges of a switch box's box ([0.85, 1.05] in the
   max-norm, less the middle of its right edge, where the door's dark handle lies);
2. trim candidates: band pixels that look like none of the background (any pixel of the
   ring just outside the box) nor, for a switch box, the door's body (its interior
   median) or that body shaded (the shadow line inside the frame, the enclosure);
3. for each palette colour c, the residual of every candidate to the nearest blend
   `α·k·c + (1 − α)·n` (k: shading, 0.55–1.1; α ≥ 0.5: at least half trim; n: one of
   those neighbour colours); the colour with the smallest median residual wins. The blend is
   fitted apart in luma and in chroma (YCbCr, sharing k and n; `_residuals`): a camera's stream
   (MJPEG, H.264) codes chroma at half resolution (4:2:0), one colour for each 2×2 pixels, so
   a 1 px trim keeps its own luma but only a share of its chroma, and a switch box's frame,
   the thinnest trim, is allowed a chroma share down to 0.25.

Measured with the shipped detector's boxes on 100 rendered scenes never used to tune
it (seeds 200–259 and 300–339, 1.5–3 m away): 95 right (gauge 36/37, valve 33/34,
switch box 26/29); the first version (no handle cut-out, no shadow) read 84 % of
switch boxes.

A switch box's frame is 1–2 px wide, and a detector's box is off by about as much (4–6 % of its
side): the band then holds the door or the wall, read as grey or black (40 of 214 fully visible
switch boxes wrong on `data/pval` around the detector's boxes, 5 of 216 around the truth's). So a
switch box's box is first snapped to its door (`_door_box`): the connected region of pixels like
the door's body that holds the box's middle, its bounding box grown by `_FRAME_PX`, each side
kept from the detector where the door's region meets the end of what was looked at (the image's
edge, or a wall as light as the door). Tuned by a throwaway script on the validation sets
(`data/pval`, `data/pval_twins`: the shipped detector's boxes, switch boxes fully in view): 202/214
and 112/120 right, against 174/214 and 101/120 without it (docs/targets.md). The figure anyone can
rerun, on scenes no tuning saw: `dronectl bench perception --test 1 --test-empty 1 --validation 1
--validation-empty 1 --frames 1 --targets 2-4 --multi 400` reads the colour of 95.23 % of the matched
targets at the shipped threshold, against 91.20 % before.

A gauge's band also holds the rim of its white dial and the dial's black ticks, which grey and black
explain. On a small or tilted gauge those are most of the candidates, and their median read a blue
or red bezel grey (10 of the 12 colour misreads of the named targets on `data/twins`' test images,
looked at with a throwaway script).
So where the median names an unsaturated colour for a gauge, a saturated one (red, blue, yellow)
wins if it is the close best explanation of at least 15 % of the candidates (`_saturated_bezel`;
the values were the first tried, on the validation folders). The shipped detector's boxes on
validation, a throwaway count (every matched target, gauges alone): 338 → 353 of 386 gauges right,
valves and switch boxes unchanged. On scenes no tuning saw, the command above, 2026-11-27: 94.70 %
(769/812) → **95.94 %** (779/812) of matched targets at the shipped threshold.

A round target cut by the image's edge: the detector predicts its box past the edge (`ImageDetector`
reads around that whole box), but often short of the whole ring, so the box's annulus falls on the
dial and a red, blue or yellow trim reads grey or black. A gauge's or valve's box that meets the edge
on one side is therefore grown past it to its uncut side (`_beyond_the_edge`: a round target is as
wide as it is tall). A throwaway count on the validation folders (`data/pval`, `data/pval_twins`,
every matched target cut by the edge): 108 → 126 of 142 right (gauges 29 → 42 of 49, valves 26 → 31
of 38); fully visible targets unchanged (938/981).

Luma and chroma fitted apart, 2026-11-28. Tuned with throwaway scripts on the validation folders
(`data/pval`, `data/pval_twins`: the shipped detector's boxes on every matched target, each picture
also re-encoded as the simulated stream sends it, JPEG quality 85 at 4:2:0), against the RGB fit:
lossless 704/747 → 706/747 and 360/376 → 359/376 right; through the JPEG 667/746 → 692/746 and
320/374 → 331/374. A chroma share down to 0.25 for gauges and valves too read fewer gauges on both.
On scenes no tuning saw, the command above: lossless 95.94 % → 96.18 % (781/812) of matched targets;
as a stream camera receives them (its "through the stream's JPEG" line) 88.59 % (722/815) →
**91.78 %** (748/815). That is still below the lossless figure: on a small gauge the white dial
outvotes a bezel whose chroma the JPEG has spread, and a red frame on a brick-red wall has little
chroma left to tell from the wall.

Numpy and one OpenCV labelling; about a millisecond per box.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from drone_inspect_core.vocabulary import shipped_vocabulary

_NAMES: tuple[str, ...] = shipped_vocabulary().colour_names
_PALETTE = np.array([shipped_vocabulary().colours[n].rgb for n in _NAMES], dtype=np.float32)  # (C, 3)
_SATURATED = (_PALETTE.max(axis=1) - _PALETTE.min(axis=1)) / np.maximum(_PALETTE.max(axis=1), 1.0) > 0.3
"""Palette colours with a hue (red, blue, yellow), against black and grey."""
_HIT_RESIDUAL = 25.0  # a candidate this close (YCbCr, 8-bit) to a colour's blends is that colour's
_HIT_SHARE = 0.15  # of the candidates, for a saturated colour to win a gauge's reading (`_saturated_bezel`)
_SHADES = np.linspace(0.55, 1.1, 6, dtype=np.float32)
_TRIM_SHARES = np.linspace(0.5, 1.0, 5, dtype=np.float32)
_CHROMA_SHARES: dict[str, np.ndarray] = {"switchbox": np.linspace(0.25, 1.0, 7, dtype=np.float32)}
"""A trim's share of its pixels' chroma where not `_TRIM_SHARES`: a switch box's frame, the thinnest trim."""
_YCBCR = np.array(
    [[0.299, 0.587, 0.114], [-0.168736, -0.331264, 0.5], [0.5, -0.418688, -0.081312]], dtype=np.float32
)
"""RGB to (Y, Cb, Cr), BT.601 as JPEG's: the luma and chroma a stream codes."""
_BANDS: dict[str, tuple[float, float]] = {
    "gauge": (0.72, 1.05),
    "valve": (0.72, 1.05),
    "switchbox": (0.85, 1.05),
}
_ROUND_BAND = _BANDS["gauge"]
_OUTSIDE = (1.15, 1.5)  # the background ring, in box half-axes
_HANDLE_X = 0.75  # a switch box's band leaves out its right edge beyond this (the handle), except the corners
_INSIDE = 0.6  # the door body of a switch box: within this of the centre
_SHADOW = 0.7  # the door's shadow line inside its frame and the enclosure behind it: the body colour shaded
_CANDIDATE_DISTANCE = 35.0  # a trim candidate differs from every background pixel by more (8-bit RGB)
_MAX_BACKGROUND = 128  # background pixels compared against, evenly subsampled
_MAX_BAND = 192  # band pixels looked at, evenly subsampled
_MAX_CANDIDATES = 64  # trim candidates scored, evenly subsampled (a large box's band has hundreds)
_DOOR_LIKE = 40.0  # a pixel within this of the door body's median colour is door (8-bit RGB)
_DOOR_SEARCH = 1.3  # the door is looked for within this of the box's centre, in half-axes
_DOOR_SIZE = (0.6, 1.3)  # a door region outside these fractions of the box's sides is not the door
_FRAME_PX = 1.0  # the frame around the door, as the box's band expects it
_EDGE_PX = 1.0  # a box side this close to the image's edge is cut by it


@dataclass(frozen=True)
class ColourRead:
    """A trim's colour as read: its name (`drone_inspect_core.vocabulary`) and `doubt`, lower for a surer
    read. Here (the rule reader) the median distance (YCbCr, 8-bit) of the trim candidates to that
    colour's nearest blends; the learned reader's is 1 − p(colour) (`perception.colour_model`). Of two
    twins that both read the colour asked for, the misread one mostly has the larger doubt
    (`controller.planning.grounding.select_target` has the counts)."""

    name: str
    doubt: float


def read_attribute(
    image: np.ndarray, bbox_px: tuple[float, float, float, float], kind: str | None
) -> str | None:
    """The trim colour name (`drone_inspect_core.vocabulary`) of the target in `bbox_px`,
    or None (`read_colour`'s name)."""
    read = read_colour(image, bbox_px, kind)
    return None if read is None else read.name


def read_colour(
    image: np.ndarray, bbox_px: tuple[float, float, float, float], kind: str | None
) -> ColourRead | None:
    """The trim colour of the target in `bbox_px` and how well it fits, or None.

    `kind` picks the band (a switch box's frame, else a ring); None when the box is
    degenerate or has too few pixels around it to compare with.
    """
    bbox_px = trim_box(image, bbox_px, kind)
    band, outside, inside = _regions(image, bbox_px, kind)
    if len(band) < 4 or len(outside) < 4:
        return None
    neighbours = [np.median(outside, axis=0)]
    if kind == "switchbox" and len(inside):
        body = np.median(inside, axis=0)
        neighbours += [body, _SHADOW * body]
    band = _subsample(band, _MAX_BAND)
    reference = np.concatenate([_subsample(outside, _MAX_BACKGROUND), np.stack(neighbours)])
    distance = np.linalg.norm(band[:, None, :] - reference[None], axis=2).min(axis=1)  # (N,)
    candidates = band[distance > _CANDIDATE_DISTANCE]
    if len(candidates) < 2:
        candidates = band
    candidates = _subsample(candidates, _MAX_CANDIDATES)
    residual = _residuals(candidates, np.stack(neighbours), _CHROMA_SHARES.get(kind or "", _TRIM_SHARES))
    fits = np.median(residual, axis=1)
    choice = int(np.argmin(fits))
    if kind == "gauge" and not _SATURATED[choice]:
        bezel = _saturated_bezel(residual)
        choice = choice if bezel is None else bezel
    return ColourRead(_NAMES[choice], float(fits[choice]))


def trim_box(
    image: np.ndarray, bbox_px: tuple[float, float, float, float], kind: str | None
) -> tuple[float, float, float, float]:
    """The box a trim is read around: a switch box's snapped to its door (`_door_box`), a round target's
    cut by the image's edge grown past it to the whole ring (`_beyond_the_edge`). The learned reader
    (`perception.colour_model`) reads around it too."""
    if kind == "switchbox":
        return _door_box(image, bbox_px) or bbox_px
    return _beyond_the_edge(bbox_px, image.shape[1], image.shape[0])


def _residuals(candidates: np.ndarray, neighbours: np.ndarray, chroma_shares: np.ndarray) -> np.ndarray:
    """(C, N): each candidate's distance (YCbCr) to the nearest blend of palette colour c with a neighbour.

    The blend `a·k·c + (1 − a)·n` (k in `_SHADES`, n a neighbour) is fitted apart in luma (a in
    `_TRIM_SHARES`) and in chroma (a in `chroma_shares`), sharing k and n: a stream's 4:2:0 chroma
    holds one colour for each 2×2 pixels, so a 1 px trim's pixels keep their own luma but only a
    share of their chroma (see the module docstring)."""
    ycc = candidates @ _YCBCR.T  # (N, 3)
    palette, around = _PALETTE @ _YCBCR.T, neighbours @ _YCBCR.T  # (C, 3), (M, 3)

    def blends(shares: np.ndarray) -> np.ndarray:
        """[c, m, k, a, channel] = a·k·palette[c] + (1 − a)·around[m]"""
        share = shares[None, None, None, :, None]
        trim = palette[:, None, None, None, :] * (_SHADES[None, None, :, None, None] * share)
        return trim + around[None, :, None, None, :] * (1.0 - share)

    at = ycc[None, :, None, None, None, :]  # against blends[:, None]: (C, N, M, K, A, channel)
    luma = ((at[..., :1] - blends(_TRIM_SHARES)[:, None, ..., :1]) ** 2).sum(axis=5).min(axis=4)
    chroma = ((at[..., 1:] - blends(chroma_shares)[:, None, ..., 1:]) ** 2).sum(axis=5).min(axis=4)
    return np.sqrt(luma + chroma).min(axis=(2, 3))


def _saturated_bezel(residual: np.ndarray) -> int | None:
    """A saturated palette colour that is the close best explanation (`_HIT_RESIDUAL`) of at least
    `_HIT_SHARE` of the candidates (and 3), the most such; None when there is none. A gauge's band also
    holds its dial's white face and black ticks, which the unsaturated colours explain: on a small or
    tilted gauge they are most of the candidates, and their median read a blue bezel grey."""
    best = residual.argmin(axis=0)
    close = residual[best, np.arange(residual.shape[1])] < _HIT_RESIDUAL
    hits = np.where(_SATURATED, np.bincount(best[close], minlength=len(_NAMES)), 0)
    colour = int(np.argmax(hits))
    return colour if hits[colour] >= max(3, _HIT_SHARE * residual.shape[1]) else None


def _door_box(
    image: np.ndarray, bbox_px: tuple[float, float, float, float]
) -> tuple[float, float, float, float] | None:
    """A switch box's box snapped to its door (see the module docstring), or None when no region like
    the door's body fits the box (a door as dark as its icons, a box that is not a switch box)."""
    height, width = image.shape[:2]
    u0, v0, u1, v1 = bbox_px
    cu, cv = (u0 + u1) / 2.0, (v0 + v1) / 2.0
    ru, rv = (u1 - u0) / 2.0, (v1 - v0) / 2.0
    if not (ru >= 2.0 and rv >= 2.0):
        return None
    left, top = max(0, int(cu - _DOOR_SEARCH * ru)), max(0, int(cv - _DOOR_SEARCH * rv))
    right = min(width, int(np.ceil(cu + _DOOR_SEARCH * ru)))
    bottom = min(height, int(np.ceil(cv + _DOOR_SEARCH * rv)))
    mu0, mu1 = max(left, int(cu - 0.5 * ru)), min(right, int(cu + 0.5 * ru) + 1)
    mv0, mv1 = max(top, int(cv - 0.5 * rv)), min(bottom, int(cv + 0.5 * rv) + 1)
    if right - left < 3 or bottom - top < 3 or mu1 <= mu0 or mv1 <= mv0:
        return None
    region = image[top:bottom, left:right].astype(np.float32)
    body = np.median(image[mv0:mv1, mu0:mu1].reshape(-1, 3).astype(np.float32), axis=0)
    door = (np.linalg.norm(region - body, axis=2) < _DOOR_LIKE).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(door, connectivity=4)
    middle = labels[mv0 - top : mv1 - top, mu0 - left : mu1 - left]
    votes = np.bincount(middle.ravel(), minlength=count)
    votes[0] = 0  # not door
    label = int(np.argmax(votes))
    if votes[label] == 0:
        return None
    x, y, w, h = (int(v) for v in stats[label, :4])
    if not (_DOOR_SIZE[0] * 2 * ru <= w <= _DOOR_SIZE[1] * 2 * ru):
        return None
    if not (_DOOR_SIZE[0] * 2 * rv <= h <= _DOOR_SIZE[1] * 2 * rv):
        return None
    # A side where the door's region reaches the end of the search was not found: the detector's stays.
    found_u0 = left + x - _FRAME_PX if x > 0 else u0
    found_v0 = top + y - _FRAME_PX if y > 0 else v0
    found_u1 = left + x + w + _FRAME_PX if x + w < right - left else u1
    found_v1 = top + y + h + _FRAME_PX if y + h < bottom - top else v1
    return (float(found_u0), float(found_v0), float(found_u1), float(found_v1))


def _beyond_the_edge(
    bbox_px: tuple[float, float, float, float], width: int, height: int
) -> tuple[float, float, float, float]:
    """A round target's box cut by the image's edge, grown past that edge to the round target's width
    (its uncut side): the box of the whole ring, of which the image holds a part. Cut on both sides of
    one axis, or on two axes, the box stays as it is."""
    u0, v0, u1, v1 = bbox_px
    cut_u = (u0 <= _EDGE_PX, u1 >= width - _EDGE_PX)
    cut_v = (v0 <= _EDGE_PX, v1 >= height - _EDGE_PX)
    if (any(cut_u) and any(cut_v)) or all(cut_u) or all(cut_v):
        return bbox_px
    side_u, side_v = u1 - u0, v1 - v0
    if any(cut_u) and side_u < side_v:
        return (u1 - side_v, v0, u1, v1) if cut_u[0] else (u0, v0, u0 + side_v, v1)
    if any(cut_v) and side_v < side_u:
        return (u0, v1 - side_u, u1, v1) if cut_v[0] else (u0, v0, u1, v0 + side_u)
    return bbox_px


def _regions(
    image: np.ndarray, bbox_px: tuple[float, float, float, float], kind: str | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(band, outside ring, inside) pixels as float32 (N, 3) arrays."""
    height, width = image.shape[:2]
    u0, v0, u1, v1 = bbox_px
    cu, cv = (u0 + u1) / 2.0, (v0 + v1) / 2.0
    ru, rv = (u1 - u0) / 2.0, (v1 - v0) / 2.0
    empty = np.zeros((0, 3), np.float32)
    if not (ru >= 1.0 and rv >= 1.0):
        return empty, empty, empty
    reach = _OUTSIDE[1]
    left, right = max(0, int(np.floor(cu - reach * ru))), min(width, int(np.ceil(cu + reach * ru)))
    top, bottom = max(0, int(np.floor(cv - reach * rv))), min(height, int(np.ceil(cv + reach * rv)))
    if right <= left or bottom <= top:
        return empty, empty, empty
    vv, uu = np.mgrid[top:bottom, left:right]
    x, y = (uu + 0.5 - cu) / ru, (vv + 0.5 - cv) / rv  # pixel centres in box half-axes
    r = (np.maximum(np.abs(x), np.abs(y)) if kind == "switchbox" else np.hypot(x, y)).ravel()
    pixels = image[top:bottom, left:right].reshape(-1, 3).astype(np.float32)
    low, high = _BANDS.get(kind or "", _ROUND_BAND)
    band = (r >= low) & (r <= high)
    if kind == "switchbox":  # the door's dark handle lies against the right edge of the frame
        band &= ~((x > _HANDLE_X) & (np.abs(y) < _HANDLE_X)).ravel()
    return (
        pixels[band],
        pixels[(r >= _OUTSIDE[0]) & (r <= _OUTSIDE[1])],
        pixels[r <= _INSIDE],
    )


def _subsample(pixels: np.ndarray, most: int) -> np.ndarray:
    if len(pixels) <= most:
        return pixels
    return pixels[np.linspace(0, len(pixels) - 1, most).astype(int)]
