"""Quaternion and 3-vector helpers on plain Python floats, for the 240 Hz hot path.

Quaternions are (x, y, z, w) tuples as in PyBullet, rotating body vectors into
the world. numpy is avoided on purpose: for 3- and 4-vectors its per-call
overhead is several times the arithmetic.
"""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def quat_rotate(q: Quat, v: Vec3) -> Vec3:
    """Rotate v by the unit quaternion q (body to world)."""
    x, y, z, w = q
    vx, vy, vz = v
    # t = 2 q_vec × v ; v' = v + w t + q_vec × t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )


def quat_rotate_inverse(q: Quat, v: Vec3) -> Vec3:
    """Rotate v by the inverse of q (world to body)."""
    x, y, z, w = q
    return quat_rotate((-x, -y, -z, w), v)


def quat_multiply(a: Quat, b: Quat) -> Quat:
    """The Hamilton product a ⊗ b (apply b first, then a)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def quat_conjugate(q: Quat) -> Quat:
    """The inverse of a unit quaternion."""
    return (-q[0], -q[1], -q[2], q[3])


def quat_from_yaw(yaw_rad: float) -> Quat:
    """A pure rotation about world z (up)."""
    return (0.0, 0.0, math.sin(0.5 * yaw_rad), math.cos(0.5 * yaw_rad))


def quat_between(src: Vec3, dst: Vec3) -> Quat:
    """The shortest rotation taking unit vector src onto unit vector dst."""
    cx = src[1] * dst[2] - src[2] * dst[1]
    cy = src[2] * dst[0] - src[0] * dst[2]
    cz = src[0] * dst[1] - src[1] * dst[0]
    dot = src[0] * dst[0] + src[1] * dst[1] + src[2] * dst[2]
    if cx * cx + cy * cy + cz * cz < 1e-12 and dot < 0.0:
        # Opposite vectors: turn half a circle about any axis orthogonal to src.
        ax, ay, az = (0.0, -src[2], src[1]) if abs(src[0]) < 0.9 else (-src[1], src[0], 0.0)
        n = math.sqrt(ax * ax + ay * ay + az * az)
        return (ax / n, ay / n, az / n, 0.0)
    w = dot + 1.0
    n = math.sqrt(cx * cx + cy * cy + cz * cz + w * w)
    return (cx / n, cy / n, cz / n, w / n)


def quat_from_z_axis_and_yaw(z_axis: Vec3, yaw_rad: float) -> Quat:
    """The attitude whose body z is the unit vector z_axis and whose heading is yaw_rad (ENU).

    Body x is the heading direction projected onto the plane normal to z_axis.
    """
    zx, zy, zz = z_axis
    hx, hy = math.cos(yaw_rad), math.sin(yaw_rad)
    # y = z × heading, normalised; x = y × z
    yx, yy, yz = -zz * hy, zz * hx, zx * hy - zy * hx
    n = math.sqrt(yx * yx + yy * yy + yz * yz)
    if n < 1e-6:  # thrust horizontal along the heading: keep any orthogonal y
        yx, yy, yz, n = -hy, hx, 0.0, 1.0
    yx, yy, yz = yx / n, yy / n, yz / n
    xx, xy, xz = yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx
    return _quat_from_matrix(xx, yx, zx, xy, yy, zy, xz, yz, zz)


def _quat_from_matrix(
    m00: float, m01: float, m02: float, m10: float, m11: float, m12: float, m20: float, m21: float, m22: float
) -> Quat:
    """Rotation matrix (row-major entries) to a quaternion (Shepperd's method)."""
    trace = m00 + m11 + m22
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        return ((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s)
    if m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        return (0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    if m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        return ((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)
    s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
    return ((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)


def yaw_from_quat(q: Quat) -> float:
    """Heading (ENU yaw) of the attitude q: the ZYX Euler yaw."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
