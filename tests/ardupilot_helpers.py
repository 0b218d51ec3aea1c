"""Finding a real ArduCopter SITL for the tests that fly it.

ArduPilot is looked for in $ARDUPILOT_SITL_DIR, then in `../shared/ardupilot-sitl` beside the checkout;
tests that need it are skipped, with that reason, when neither holds an ArduCopter SITL build. CI has
one, so there they run.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from sim_world.ardupilot_bridge.ardupilot_process import (
    ARDUPILOT_DIR_ENV,
    ArduPilotFolderError,
    check_ardupilot_dir,
)

SHARED_ARDUPILOT = Path(__file__).resolve().parents[2] / "shared" / "ardupilot-sitl"


def find_test_ardupilot() -> Path | None:
    for candidate in (os.environ.get(ARDUPILOT_DIR_ENV), SHARED_ARDUPILOT):
        if candidate:
            try:
                return check_ardupilot_dir(Path(candidate))
            except ArduPilotFolderError:
                continue
    return None


ARDUPILOT_DIR = find_test_ardupilot()
requires_ardupilot = pytest.mark.skipif(
    ARDUPILOT_DIR is None,
    reason=f"no ArduCopter SITL: set {ARDUPILOT_DIR_ENV} or put one at {SHARED_ARDUPILOT}",
)
