"""ArduPilot's motor outputs (PWM) → the quadrotor's rotor speed commands.

ArduCopter's quad X (FRAME_CLASS 1, FRAME_TYPE 1) drives SERVO1..4 = motors 1..4: 1 front right
(counter-clockwise seen from above), 2 back left (CCW), 3 front left (clockwise), 4 back right (CW).
That is PX4's quad X numbering and spin too, and the project's rotor order
(`sim_world.physics.quadrotor`: 0 front-right CCW, 1 rear-left CCW, 2 front-left CW, 3 rear-right
CW), so servo channel i drives rotor i.

The ESC is taken as speed-linear: ω = u · ω_max with u = (pwm − MOT_PWM_MIN) / (MOT_PWM_MAX −
MOT_PWM_MIN), so thrust = kf ω² = T_max u². Over ArduPilot's output range (MOT_SPIN_MIN 0.15 to
MOT_SPIN_MAX 0.95) that curve is ArduPilot's own thrust model (1 − e)·r + e·r² best fitted with
e = MOT_THST_EXPO = 0.65 (least squares, `docs/ardupilot.md`), the value ArduPilot's own SITL uses:
the mapping needs no ArduPilot parameter of its own. A PWM at or below MOT_PWM_MIN (disarmed, or
a channel ArduPilot leaves at 0) stops the rotor.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

QUAD_X_CHANNELS = (0, 1, 2, 3)
"""The servo channel of each of the project's rotors 0..3 (ArduPilot motor i+1 on SERVO i+1)."""


@dataclass(frozen=True)
class PwmToRotor:
    """PWM (µs) → rotor speed command (rad/s), linear in speed between `pwm_min_us` and `pwm_max_us`."""

    max_rad_s: float
    pwm_min_us: float = 1000.0
    pwm_max_us: float = 2000.0

    def __post_init__(self) -> None:
        if not (self.max_rad_s > 0 and 0 < self.pwm_min_us < self.pwm_max_us):
            raise ValueError(f"PwmToRotor needs max_rad_s > 0 and 0 < pwm_min_us < pwm_max_us, got {self}")

    def throttle(self, pwm_us: float) -> float:
        """u in [0, 1]."""
        u = (pwm_us - self.pwm_min_us) / (self.pwm_max_us - self.pwm_min_us)
        return 0.0 if u <= 0.0 else min(u, 1.0)

    def rotor_speeds(self, pwm_us: Sequence[int]) -> list[float]:
        """The four rotor speed commands for one servo packet's channels."""
        return [self.throttle(pwm_us[channel]) * self.max_rad_s for channel in QUAD_X_CHANNELS]

    def spinning(self, pwm_us: Sequence[int]) -> bool:
        """Whether ArduPilot drives any motor (armed: at least MOT_SPIN_ARM)."""
        return any(pwm_us[channel] > self.pwm_min_us for channel in QUAD_X_CHANNELS)
