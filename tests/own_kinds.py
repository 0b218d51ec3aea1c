"""A target kind of the tests' own, as a user would add one: a real photograph on a panel.

The face is a photograph an installed package ships (scikit-image's `coffee.png`, a cup of
coffee on a saucer, seen from above): nothing is downloaded, and no model has seen it.
"""

from __future__ import annotations

from pathlib import Path

import skimage

MUG_PHOTO = Path(skimage.__file__).parent / "data" / "coffee.png"
MUG = {"image": str(MUG_PHOTO), "size_m": [0.36, 0.24], "words": ["mug", "coffee cup", "cup"]}
"""The kind `mug`, as a scene or mission file writes it under `kinds:`."""
