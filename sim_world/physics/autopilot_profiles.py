"""The autopilot's climb profiles: a liftoff in velocity mode, the takeoff's trapezoid, the position loop.

A part of `sim_world.physics.autopilot.Autopilot` (a base class of it), kept apart so each
file reads on its own: these methods turn the mode's targets into velocity setpoints,
with PX4's smooth spool-up and takeoff ramp; the cascade below them is
`sim_world.physics.autopilot_control`.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

from sim_world.physics.rotations import Vec3

if TYPE_CHECKING:
    from sim_world.physics.autopilot_control import AutopilotParams

logger = logging.getLogger("sim_world.physics.autopilot")

GROUND_CLEARANCE_M = 0.05  # this far above where it stood, the vehicle has left the ground


class ClimbProfiles:
    """Setpoint profiles over the autopilot's state (`Autopilot` defines the attributes used here)."""

    params: AutopilotParams
    _lifting: bool
    _landed: bool
    _ramp_v: float
    _ramp_z: float
    _ground_z: float
    _target: Vec3

    def _liftoff_setpoint(self, vel_sp: Vec3, pos: Vec3, dt_s: float) -> tuple[Vec3, float] | None:
        """VELOCITY from the ground: None while it should stay landed, else the ramped climb.

        The climb setpoint rises at takeoff_acc_m_s2 up to the commanded climb (a smooth
        spool-up, as PX4's takeoff ramp); horizontal setpoints wait until it is off the ground.
        Returns the velocity setpoint (ENU) and the ramp's acceleration as a feedforward.
        """
        prm = self.params
        climb = vel_sp[2]
        if not self._lifting:
            if climb <= prm.takeoff_trigger_speed_m_s:
                return None
            logger.debug("liftoff: climb setpoint %.2f m/s", climb)
            self._lifting = True
            self._ramp_v = 0.0
            self._ground_z = pos[2]
        elif self._landed and climb <= 0.0:  # asked down again before it left the ground
            self._lifting = False
            return None
        if self._landed and pos[2] > self._ground_z + GROUND_CLEARANCE_M:
            logger.debug("liftoff: off the ground")
            self._landed = False
        previous_v = self._ramp_v
        self._ramp_v = min(self._ramp_v + prm.takeoff_acc_m_s2 * dt_s, max(climb, 0.0))
        if not self._landed and self._ramp_v >= climb:
            self._lifting = False  # the ramp has reached the setpoint: plain velocity control from here
        acc_ff_up = min(max((self._ramp_v - previous_v) / dt_s, 0.0), prm.takeoff_acc_m_s2)
        if self._landed:
            return (0.0, 0.0, self._ramp_v), acc_ff_up
        return (vel_sp[0], vel_sp[1], self._ramp_v), acc_ff_up

    def _takeoff_setpoint(self, pos: Vec3, dt_s: float) -> tuple[Vec3, float]:
        """Advance the altitude setpoint along a trapezoidal climb profile.

        Returns the velocity setpoint (position loop + profile speed) and the profile's acceleration.
        """
        prm = self.params
        remaining = self._target[2] - self._ramp_z
        previous_v = self._ramp_v
        if remaining <= 0.0:  # at (or, for a takeoff commanded in the air, above) the target altitude
            self._ramp_z, self._ramp_v = self._target[2], 0.0
        else:
            self._ramp_v = min(
                prm.takeoff_speed_m_s,
                self._ramp_v + prm.takeoff_acc_m_s2 * dt_s,
                math.sqrt(2.0 * prm.takeoff_acc_m_s2 * remaining),
            )
            self._ramp_z = min(self._ramp_z + self._ramp_v * dt_s, self._target[2])
            if self._ramp_z == self._target[2]:
                self._ramp_v = 0.0
        vel_sp = self._position_loop((self._target[0], self._target[1], self._ramp_z), pos, self._ramp_v)
        return vel_sp, (self._ramp_v - previous_v) / dt_s

    def _position_loop(self, target: Vec3, pos: Vec3, feedforward_up: float) -> Vec3:
        """Position P loop → velocity setpoint (ENU), within the speed limits."""
        prm = self.params
        vx = prm.pos_p_xy * (target[0] - pos[0])
        vy = prm.pos_p_xy * (target[1] - pos[1])
        vz = prm.pos_p_z * (target[2] - pos[2]) + feedforward_up
        horizontal = math.hypot(vx, vy)
        if horizontal > prm.max_speed_xy_m_s:
            vx *= prm.max_speed_xy_m_s / horizontal
            vy *= prm.max_speed_xy_m_s / horizontal
        return (vx, vy, min(max(vz, -prm.max_speed_down_m_s), prm.max_speed_up_m_s))
