"""What an inspection target can be called: its kinds and the colour names of its attribute.

One vocabulary for every layer: the scene writes a target's kind and attribute into the
dataset manifest, the detector reports them, the instruction parser and the latent model's
training text read them. The attribute is the colour of the target's trim (a gauge's
bezel ring, a valve's handwheel, a switch box's door frame): what tells two targets of
one kind apart on the same wall ("the red valve", "the blue gauge").
"""

from __future__ import annotations

TARGET_KINDS: tuple[str, ...] = ("gauge", "valve", "switchbox")
"""The kinds of inspection target the scene builds and the detector reports."""

ATTRIBUTE_COLOURS: dict[str, tuple[int, int, int]] = {
    "black": (0x2B, 0x2B, 0x2B),
    "grey": (0xA8, 0xAC, 0xB0),
    "red": (0xC0, 0x39, 0x2B),
    "blue": (0x1F, 0x4E, 0x8C),
    "yellow": (0xD4, 0xA0, 0x17),
}
"""The trim colours by name: the scene's default `target.bezel_colours`, in the same order."""


def colour_name(rgb: tuple[int, int, int] | str) -> str:
    """The name of the attribute colour nearest to `rgb` (an (r, g, b) tuple or '#rrggbb')."""
    if isinstance(rgb, str):
        text = rgb.lstrip("#")
        if len(text) != 6:
            raise ValueError(f"{rgb!r} is not a colour of the form '#rrggbb'")
        rgb = (int(text[0:2], 16), int(text[2:4], 16), int(text[4:6], 16))
    r, g, b = (float(c) for c in rgb)
    return min(
        ATTRIBUTE_COLOURS,
        key=lambda name: sum((x - y) ** 2 for x, y in zip((r, g, b), ATTRIBUTE_COLOURS[name], strict=True)),
    )
