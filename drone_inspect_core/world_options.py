"""What a mission asks of a simulated world: where the drone starts, the wind, a bad camera.

Each is one validated model that a mission file's section is (`start:`, `wind:`, `faults.camera:`)
and the simulator reads as it is (`sim_world`: the scene places the drone at a `StartPose`, the
physics blows `WindConfig`, the video source applies `CameraFaults`). They live on the ground floor
because both sides read them and a real-vehicle mission must load no simulator module.
"""

from __future__ import annotations

import math

from pydantic import Field, model_validator

from drone_inspect_core.config_files import StrictModel


class StartPose(StrictModel):
    """Where the drone starts, relative to the pose that centres the named target (in front of it,
    looking at the wall): `right_m` > 0 puts the drone to the right, so the target appears left."""

    right_m: float = Field(default=0.0, ge=-3.0, le=3.0)
    up_m: float = Field(default=0.0, ge=-2.0, le=2.0)
    distance_m: float = Field(default=2.0, gt=0.5, le=6.0)
    yaw_deg: float = Field(default=0.0, ge=-30.0, le=30.0)

    @classmethod
    def parse(cls, text: str) -> StartPose:
        """From "right,up,distance,yaw" (metres, metres, metres, degrees); ValueError saying what is wrong."""
        parts = text.split(",")
        try:
            values = [float(v) for v in parts]
        except ValueError:
            raise ValueError(f"start offset {text!r}: expected four numbers right,up,distance,yaw") from None
        if len(values) != 4:
            raise ValueError(f"start offset {text!r}: expected four numbers right,up,distance,yaw")
        names = ("right_m", "up_m", "distance_m", "yaw_deg")
        try:
            return cls(**dict(zip(names, values, strict=True)))
        except ValueError as exc:
            first = str(exc).splitlines()
            raise ValueError(f"start offset {text!r}: {' '.join(first[1:3]).strip()}") from None


class WindConfig(StrictModel):
    """Mean wind (ENU, m/s) plus gusts (`sim_world.physics.wind.Wind`); the default is calm air.

    Gusts are isotropic (the same ``gust_std_m_s`` on all three axes), a simple, conservative
    choice: real low-altitude vertical turbulence is somewhat weaker. ``sample_period_s`` is the grid
    the gust process is drawn on; it must be well below the gust time constant.
    """

    mean_enu_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gust_std_m_s: float = Field(default=0.0, ge=0.0, le=5.0)
    gust_time_constant_s: float = Field(default=2.0, gt=0.0, le=60.0)
    sample_period_s: float = Field(default=0.05, gt=0.0)

    @model_validator(mode="after")
    def _finite(self) -> WindConfig:
        if not all(math.isfinite(v) and abs(v) <= 30.0 for v in self.mean_enu_m_s):
            raise ValueError(f"mean_enu_m_s: three numbers within ±30 m/s, got {list(self.mean_enu_m_s)}")
        if self.sample_period_s > self.gust_time_constant_s:
            raise ValueError(
                f"sample_period_s: must be at most gust_time_constant_s ({self.gust_time_constant_s:g}), "
                f"got {self.sample_period_s:g}"
            )
        return self


class CameraFaults(StrictModel):
    """A bad camera on purpose, at its source: dropped frames, a frozen picture, a stream that dies.

    Times are simulated seconds since the vehicle started (a mission's loop typically begins 10-20 s
    in, after readiness, arming and the takeoff). While frozen, the last image is sent again and again
    (new frame numbers, the same picture, as a stuck encoder does). A dead stream closes the server.
    """

    drop: float = Field(default=0.0, ge=0.0, lt=1.0)
    """The fraction of rendered frames never sent."""
    freeze_at_s: float | None = Field(default=None, ge=0.0)
    freeze_for_s: float = Field(default=3.0, gt=0.0)
    dies_at_s: float | None = Field(default=None, ge=0.0)
    seed: int = Field(default=0, ge=0)
