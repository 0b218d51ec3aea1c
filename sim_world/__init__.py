"""sim_world: the simulated world (PyBullet), the simulated vehicle, the PX4 and ArduPilot bridges.

The only package that imports PyBullet. PyBullet's C library prints its build time on stderr when it
loads ("pybullet build time: ..."), before any message of ours: the first import of this package
loads it with stderr silenced (file descriptor 2, where C writes), so a command's own first line is
its first line. Nothing is hidden when PyBullet is missing: the import error comes where it is used.
"""

from __future__ import annotations

import contextlib
import os
import sys


def _load_pybullet_quietly() -> None:
    if "pybullet" in sys.modules:
        return
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no file descriptor 2 to silence: load it as it is
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 2)
            with contextlib.suppress(ImportError):
                import pybullet  # noqa: F401
    finally:
        os.dup2(saved, 2)
        os.close(saved)


_load_pybullet_quietly()
