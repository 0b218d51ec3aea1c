"""The control cascade of the simulated autopilot, modelled on PX4's multicopter stack.

velocity (PI, anti-windup, tilt and thrust limits) → thrust vector + yaw
→ attitude (PX4's quaternion law with yaw de-prioritised) → body rates (PID)
→ mixer (X-quad, torques and thrust to ω², saturation: roll/pitch, then thrust, then yaw).

Everything runs in the simulator's frames (world ENU, body FLU); the flight
interface's NED/FRD setpoints are converted by `sim_world.physics.autopilot`. The loops
run once per physics step (240 Hz) on plain floats (see `sim_world.physics.rotations`).
Gains are PX4's defaults where PX4 has a directly comparable parameter (named in
the docstrings), otherwise tuned on `QuadrotorParams`' default airframe.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim_world.physics.quadrotor import GRAVITY_M_S2, ROTOR_YAW_SIGN, QuadrotorParams
from sim_world.physics.rotations import (
    Quat,
    Vec3,
    quat_between,
    quat_conjugate,
    quat_from_z_axis_and_yaw,
    quat_multiply,
    quat_rotate,
    quat_rotate_inverse,
)


@dataclass(frozen=True)
class AutopilotParams:
    """Gains and limits of the cascade and of the flight modes (PX4 parameter names in brackets)."""

    pos_p_xy: float = 0.95
    """Horizontal position gain, (m/s)/m [MPC_XY_P]."""
    pos_p_z: float = 1.0
    """Vertical position gain, (m/s)/m [MPC_Z_P]."""
    vel_p_xy: float = 3.0
    """Horizontal velocity gain, (m/s²)/(m/s) [MPC_XY_VEL_P_ACC; PX4 1.8, raised for a crisp 0.5 m/s step]."""
    vel_i_xy: float = 1.0
    """Horizontal velocity integral gain, (m/s²)/m [MPC_XY_VEL_I_ACC]: removes the drag offset."""
    vel_p_z: float = 4.0
    """Vertical velocity gain [MPC_Z_VEL_P_ACC]."""
    vel_i_z: float = 2.0
    """Vertical velocity integral gain [MPC_Z_VEL_I_ACC]."""
    max_speed_xy_m_s: float = 3.0
    """Horizontal speed limit for all setpoints [MPC_XY_VEL_MAX]; inspection flight is slow."""
    max_speed_up_m_s: float = 1.5
    """Climb rate limit [MPC_Z_VEL_MAX_UP]."""
    max_speed_down_m_s: float = 1.0
    """Descent rate limit [MPC_Z_VEL_MAX_DN]."""
    max_acc_xy_m_s2: float = 5.0
    """Horizontal acceleration limit of the velocity loop."""
    max_tilt_deg: float = 35.0
    """Tilt limit [MPC_TILTMAX_AIR]."""
    thrust_min_fraction: float = 0.12
    """Lowest collective thrust in flight, as a fraction of the maximum [MPC_THR_MIN]."""
    thrust_max_fraction: float = 0.9
    """Highest collective thrust, leaving headroom for attitude control [MPC_THR_MAX]."""
    att_p_roll_pitch: float = 6.5
    """Attitude gain, (rad/s)/rad [MC_ROLL_P, MC_PITCH_P]."""
    att_p_yaw: float = 2.8
    """Yaw attitude gain [MC_YAW_P]."""
    yaw_weight: float = 0.4
    """How much yaw error counts while tilt is being corrected [MC_YAW_WEIGHT]."""
    max_rate_roll_pitch_deg_s: float = 220.0
    """Body rate limit for roll and pitch [MC_ROLLRATE_MAX]."""
    max_rate_yaw_deg_s: float = 120.0
    """Body rate limit for yaw [MC_YAWRATE_MAX]."""
    rate_p_roll_pitch: float = 20.0
    """Rate gain as angular acceleration per rate error, 1/s (scaled by inertia into torque)."""
    rate_i_roll_pitch: float = 10.0
    """Rate integral gain, 1/s²."""
    rate_d_roll_pitch: float = 0.2
    """Rate derivative gain (on the measured rate), dimensionless."""
    rate_p_yaw: float = 8.0
    """Yaw rate gain, 1/s."""
    rate_i_yaw: float = 4.0
    """Yaw rate integral gain, 1/s²."""
    rate_integral_limit_rad_s2: float = 20.0
    """Bound on each rate integrator's angular acceleration."""
    idle_rotor_fraction: float = 0.15
    """Armed rotor speed as a fraction of the maximum (spinning, not lifting)."""
    takeoff_speed_m_s: float = 1.5
    """Climb rate during takeoff [MPC_TKO_SPEED, PX4's default 1.5 m/s]."""
    takeoff_acc_m_s2: float = 2.0
    """Acceleration of the takeoff climb profile (speeding up at the start, slowing down at the top),
    and of the climb ramp when a velocity setpoint lifts the vehicle off (below MPC_ACC_UP_MAX, 4 m/s²)."""
    takeoff_trigger_speed_m_s: float = 0.3
    """A landed vehicle in VELOCITY mode lifts off when the setpoint climbs faster than this
    (PX4's velocity-triggered takeoff in FlightTask::_checkTakeoff)."""
    takeoff_acceptance_m: float = 0.1
    """Takeoff ends (→ HOLD) when the altitude is within this of the target."""
    max_takeoff_altitude_m: float = 50.0
    """Refuse takeoffs above this (a sane bound for inspection flights)."""
    land_speed_m_s: float = 0.5
    """Descent rate during land [MPC_LAND_SPEED]."""
    land_detect_time_s: float = 0.3
    """Touchdown is declared after this long with no vertical motion and low thrust [LNDMC_TRIG_TIME]."""
    max_yawspeed_deg_s: float = 60.0
    """Yaw-rate setpoint limit for velocity commands [MPC_MAN_Y_MAX]."""

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"AutopilotParams.{name} must be a finite number >= 0, got {value}")
        if not 0.0 < self.max_tilt_deg < 80.0:
            raise ValueError(f"AutopilotParams.max_tilt_deg must be in (0, 80), got {self.max_tilt_deg}")
        if not 0.0 <= self.thrust_min_fraction < self.thrust_max_fraction <= 1.0:
            raise ValueError("AutopilotParams: need 0 <= thrust_min_fraction < thrust_max_fraction <= 1")
        if not 0.0 <= self.idle_rotor_fraction < 1.0:
            raise ValueError(
                f"AutopilotParams.idle_rotor_fraction must be in [0, 1), got {self.idle_rotor_fraction}"
            )
        if not 0.0 < self.yaw_weight <= 1.0:
            raise ValueError(f"AutopilotParams.yaw_weight must be in (0, 1], got {self.yaw_weight}")


def _clamp(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


class VelocityController:
    """Velocity PI → desired thrust acceleration vector (ENU, gravity included), as PX4's PositionControl."""

    def __init__(self, params: AutopilotParams, quad: QuadrotorParams) -> None:
        self.p = params
        self._tan_tilt = math.tan(math.radians(params.max_tilt_deg))
        self._acc_min = params.thrust_min_fraction * quad.max_thrust_n / quad.mass_kg
        self._acc_max = params.thrust_max_fraction * quad.max_thrust_n / quad.mass_kg
        self.reset()

    def reset(self) -> None:
        """Clear the integrators (on the ground, on mode resets)."""
        self._int_x = self._int_y = self._int_z = 0.0

    def update(self, vel_sp: Vec3, vel: Vec3, dt_s: float, acc_ff_up_m_s2: float = 0.0) -> Vec3:
        """The thrust acceleration (m/s², ENU) that drives vel towards vel_sp within the limits.

        acc_ff_up_m_s2 is a vertical acceleration feedforward (from a climb profile).
        """
        prm = self.p
        ex, ey, ez = vel_sp[0] - vel[0], vel_sp[1] - vel[1], vel_sp[2] - vel[2]
        ax = prm.vel_p_xy * ex + self._int_x
        ay = prm.vel_p_xy * ey + self._int_y
        az = prm.vel_p_z * ez + self._int_z + GRAVITY_M_S2 + acc_ff_up_m_s2
        az = _clamp(az, self._acc_min, self._acc_max)
        # Vertical first, horizontal with what the tilt and thrust limits leave (PX4's priority).
        xy_max = min(
            az * self._tan_tilt,
            math.sqrt(max(self._acc_max * self._acc_max - az * az, 0.0)),
            prm.max_acc_xy_m_s2,
        )
        norm_xy = math.hypot(ax, ay)
        if norm_xy > xy_max:
            scale = xy_max / norm_xy
            lim_x, lim_y = ax * scale, ay * scale
            # Tracking anti-windup: feed the unachievable part back into the integrated error.
            arw = 2.0 / prm.vel_p_xy if prm.vel_p_xy > 0.0 else 0.0
            ex -= arw * (ax - lim_x)
            ey -= arw * (ay - lim_y)
            ax, ay = lim_x, lim_y
        if (az >= self._acc_max and ez > 0.0) or (az <= self._acc_min and ez < 0.0):
            ez = 0.0  # vertical saturation: stop integrating towards it
        self._int_x += prm.vel_i_xy * ex * dt_s
        self._int_y += prm.vel_i_xy * ey * dt_s
        self._int_z += prm.vel_i_z * ez * dt_s
        int_xy = math.hypot(self._int_x, self._int_y)
        if int_xy > prm.max_acc_xy_m_s2:
            self._int_x *= prm.max_acc_xy_m_s2 / int_xy
            self._int_y *= prm.max_acc_xy_m_s2 / int_xy
        self._int_z = _clamp(self._int_z, -GRAVITY_M_S2, GRAVITY_M_S2)
        return (ax, ay, az)


class AttitudeController:
    """PX4's quaternion attitude law: tilt first, yaw weighted down; output body rates (FLU, rad/s)."""

    def __init__(self, params: AutopilotParams) -> None:
        self._kp_rp = params.att_p_roll_pitch
        self._yaw_w = params.yaw_weight
        self._kp_yaw = params.att_p_yaw / params.yaw_weight  # PX4 compensates the weighting this way
        self._max_rp = math.radians(params.max_rate_roll_pitch_deg_s)
        self._max_yaw = math.radians(params.max_rate_yaw_deg_s)

    def update(self, q: Quat, thrust_dir: Vec3, yaw_sp_rad: float, yawspeed_ff_rad_s: float) -> Vec3:
        """Body-rate setpoint turning body z onto thrust_dir (unit, ENU) with heading yaw_sp_rad."""
        e_z = quat_rotate(q, (0.0, 0.0, 1.0))
        qd_red = quat_multiply(quat_between(e_z, thrust_dir), q)
        qd = quat_from_z_axis_and_yaw(thrust_dir, yaw_sp_rad)
        _, _, mz, mw = quat_multiply(quat_conjugate(qd_red), qd)
        if mw < 0.0:
            mz, mw = -mz, -mw
        w = self._yaw_w
        qd = quat_multiply(
            qd_red,
            (
                0.0,
                0.0,
                math.sin(w * math.asin(_clamp(mz, -1.0, 1.0))),
                math.cos(w * math.acos(_clamp(mw, -1.0, 1.0))),
            ),
        )
        ex, ey, ez, ew = quat_multiply(quat_conjugate(q), qd)
        sign = 2.0 if ew >= 0.0 else -2.0
        fx, fy, fz = quat_rotate_inverse(q, (0.0, 0.0, yawspeed_ff_rad_s))
        return (
            _clamp(sign * ex * self._kp_rp + fx, -self._max_rp, self._max_rp),
            _clamp(sign * ey * self._kp_rp + fy, -self._max_rp, self._max_rp),
            _clamp(sign * ez * self._kp_yaw + fz, -self._max_yaw, self._max_yaw),
        )


class RateController:
    """Body-rate PID → body torque (N·m, FLU), with inertia scaling and gyroscopic compensation."""

    def __init__(self, params: AutopilotParams, quad: QuadrotorParams) -> None:
        self.p = params
        self._inertia = quad.inertia_kg_m2
        self._kp = (params.rate_p_roll_pitch, params.rate_p_roll_pitch, params.rate_p_yaw)
        self._ki = (params.rate_i_roll_pitch, params.rate_i_roll_pitch, params.rate_i_yaw)
        self._kd = (params.rate_d_roll_pitch, params.rate_d_roll_pitch, 0.0)
        self.reset()

    def reset(self) -> None:
        """Clear the integrators and the derivative memory."""
        self._integral = [0.0, 0.0, 0.0]
        self._prev_rate: Vec3 | None = None

    def update(self, rate_sp: Vec3, rate: Vec3, dt_s: float, integrate: bool) -> Vec3:
        """Torque that drives the body rates towards rate_sp; integrate=False freezes the I terms."""
        prev = self._prev_rate if self._prev_rate is not None else rate
        self._prev_rate = rate
        jx, jy, jz = self._inertia
        limit = self.p.rate_integral_limit_rad_s2
        acc = [0.0, 0.0, 0.0]
        for i in range(3):
            err = rate_sp[i] - rate[i]
            acc[i] = self._kp[i] * err + self._integral[i] - self._kd[i] * (rate[i] - prev[i]) / dt_s
            if integrate:
                self._integral[i] = _clamp(self._integral[i] + self._ki[i] * err * dt_s, -limit, limit)
        wx, wy, wz = rate
        hx, hy, hz = jx * wx, jy * wy, jz * wz
        return (
            jx * acc[0] + (wy * hz - wz * hy),
            jy * acc[1] + (wz * hx - wx * hz),
            jz * acc[2] + (wx * hy - wy * hx),
        )


class Mixer:
    """X-quad mixer: collective thrust (N) and body torques (N·m) → rotor speeds (rad/s).

    When the motors cannot give everything, roll/pitch are kept first (scaled only if
    their spread alone exceeds the motor range), then collective thrust (shifted to
    fit), and yaw gets what headroom is left, as PX4's non-airmode mixer does.
    """

    def __init__(self, params: AutopilotParams, quad: QuadrotorParams) -> None:
        self._kf = quad.kf
        self._f_min = quad.kf * (params.idle_rotor_fraction * quad.max_rotor_speed_rad_s) ** 2
        self._f_max = quad.kf * quad.max_rotor_speed_rad_s**2
        a = quad.arm_length_m / math.sqrt(2.0)
        # Per-rotor thrust per unit roll torque (Σ y_i F_i), pitch torque (−Σ x_i F_i),
        # and yaw torque (Σ s_i km/kf F_i); the columns are orthogonal, so this inverts the map.
        self._roll = [y / (4.0 * a * a) for _, y, _ in quad.rotor_positions_flu_m()]
        self._pitch = [-x / (4.0 * a * a) for x, _, _ in quad.rotor_positions_flu_m()]
        self._yaw = [s * quad.kf / (4.0 * quad.km) for s in ROTOR_YAW_SIGN]
        self.saturated = False

    def mix(self, thrust_n: float, torque: Vec3) -> list[float]:
        """Rotor speed commands (PX4 quad-X order); sets `saturated` when something was cut."""
        f_min, f_max = self._f_min, self._f_max
        tx, ty, tz = torque
        rp = [self._roll[i] * tx + self._pitch[i] * ty for i in range(4)]
        saturated = False
        spread = max(rp) - min(rp)
        if spread > f_max - f_min:
            scale = (f_max - f_min) / spread
            rp = [v * scale for v in rp]
            saturated = True
        base = thrust_n / 4.0
        lo, hi = f_min - min(rp), f_max - max(rp)
        if base < lo or base > hi:
            base = _clamp(base, lo, hi)
            saturated = True
        forces = [base + v for v in rp]
        k = 1.0
        for i in range(4):
            y = self._yaw[i] * tz
            if y > 0.0 and forces[i] + y > f_max:
                k = min(k, (f_max - forces[i]) / y)
            elif y < 0.0 and forces[i] + y < f_min:
                k = min(k, (f_min - forces[i]) / y)
        if k < 1.0:
            saturated = True
        self.saturated = saturated
        kf = self._kf
        return [math.sqrt(max(forces[i] + k * self._yaw[i] * tz, 0.0) / kf) for i in range(4)]
