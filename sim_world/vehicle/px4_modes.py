"""PX4 flight modes and their MAVLink encoding.

PX4 puts its mode in HEARTBEAT.custom_mode as `main << 16 | sub << 24`; the sub
mode is only meaningful for AUTO (main 4). MAVSDK decodes exactly this to report
its `FlightMode` (OFFBOARD = main 6, HOLD = AUTO.LOITER, ...), and decides from it
whether offboard is active, so the numbers below must match PX4's
`px4_custom_mode.h`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum


class Px4MainMode(IntEnum):
    """PX4_CUSTOM_MAIN_MODE_*."""

    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7
    RATTITUDE = 8


class Px4AutoSubMode(IntEnum):
    """PX4_CUSTOM_SUB_MODE_AUTO_* (only with main mode AUTO)."""

    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6
    FOLLOW_TARGET = 8
    PRECLAND = 9


@dataclass(frozen=True)
class Px4Mode:
    """One PX4 mode: a main mode and, for AUTO, a sub mode (0 otherwise)."""

    main: int
    sub: int = 0

    @property
    def custom_mode(self) -> int:
        """The HEARTBEAT custom_mode value."""
        return (self.main & 0xFF) << 16 | (self.sub & 0xFF) << 24

    @classmethod
    def from_custom_mode(cls, custom_mode: int) -> Px4Mode:
        """Decode a HEARTBEAT custom_mode."""
        main = (custom_mode >> 16) & 0xFF
        sub = (custom_mode >> 24) & 0xFF
        return cls(main, sub if main == Px4MainMode.AUTO else 0)

    @property
    def name(self) -> str:
        """PX4's name for the mode, e.g. "OFFBOARD" or "AUTO.LOITER"."""
        try:
            main_name = Px4MainMode(self.main).name
        except ValueError:
            return f"UNKNOWN({self.main},{self.sub})"
        if self.main != Px4MainMode.AUTO:
            return main_name
        try:
            return f"AUTO.{Px4AutoSubMode(self.sub).name}"
        except ValueError:
            return f"AUTO.UNKNOWN({self.sub})"

    def __str__(self) -> str:
        return self.name


POSCTL = Px4Mode(Px4MainMode.POSCTL)
ALTCTL = Px4Mode(Px4MainMode.ALTCTL)
MANUAL = Px4Mode(Px4MainMode.MANUAL)
STABILIZED = Px4Mode(Px4MainMode.STABILIZED)
OFFBOARD = Px4Mode(Px4MainMode.OFFBOARD)
AUTO_READY = Px4Mode(Px4MainMode.AUTO, Px4AutoSubMode.READY)
AUTO_TAKEOFF = Px4Mode(Px4MainMode.AUTO, Px4AutoSubMode.TAKEOFF)
AUTO_LOITER = Px4Mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)
AUTO_MISSION = Px4Mode(Px4MainMode.AUTO, Px4AutoSubMode.MISSION)
AUTO_RTL = Px4Mode(Px4MainMode.AUTO, Px4AutoSubMode.RTL)
AUTO_LAND = Px4Mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND)

HOLD = AUTO_LOITER  # what MAVSDK and QGroundControl call "Hold"


def mode_from_set_mode(base_mode: float, custom_main: float, custom_sub: float) -> Px4Mode | None:
    """The mode a MAV_CMD_DO_SET_MODE asks for, or None when it is not a PX4 custom mode.

    MAVSDK sends (129, 6, 0) for offboard and (129, 4, 3) for hold: base_mode carries
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED (1), params 2 and 3 the main and sub mode.
    """
    if int(base_mode) & 1 == 0:
        return None
    main = int(custom_main)
    sub = int(custom_sub) if main == Px4MainMode.AUTO else 0
    return Px4Mode(main, sub)
