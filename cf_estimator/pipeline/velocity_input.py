"""Velocity messages for the aiding: geometry_msgs/TwistStamped and nav_msgs/Odometry, duck-typed.

- ``TwistStamped``: ``twist.linear`` is the velocity [m/s] in the world frame named by
  ``header.frame_id`` (mavros ``global_position/raw/gps_vel``, ``nmea_navsat_driver``'s
  ``vel``: ENU). Its axes convention is ``velocity_frame`` (ENU or NED).
- ``Odometry``: ``twist.twist.linear`` is in ``child_frame_id`` (the body, REP-105); it is
  rotated into the world (``header.frame_id``) by the message's own ``pose.pose.orientation``.

:func:`velocity_from_message` returns ``(stamp_ns, (vx, vy, vz))`` in the filter's world frame
convention (converted from ``velocity_frame`` to ``world_frame``), or a rejection reason of
:data:`cf_estimator.core.velocity.REJECT_REASONS` (plus ``malformed``). No exception escapes.
"""

from __future__ import annotations

import math
from typing import Any

Velocity = tuple[int, tuple[float, float, float]]


def message_kind(msg: Any) -> str:
    """'odometry', 'twist' or '' (neither) by the fields the message has."""
    twist = getattr(msg, "twist", None)
    if twist is None:
        return ""
    if hasattr(twist, "twist") and hasattr(msg, "pose"):
        return "odometry"
    return "twist" if hasattr(twist, "linear") else ""


def velocity_from_message(msg: Any, velocity_frame: str, world_frame: str,
                          expected_frame_id: str = "") -> Velocity | str:
    """The world-frame velocity of one message (see the module docstring) or a reason."""
    try:
        st = msg.header.stamp
        t_ns = int(st.sec) * 1_000_000_000 + int(st.nanosec)
        frame = str(msg.header.frame_id)
        kind = message_kind(msg)
        if kind == "twist":
            lin = msg.twist.linear
            v = (float(lin.x), float(lin.y), float(lin.z))
        elif kind == "odometry":
            lin = msg.twist.twist.linear
            o = msg.pose.pose.orientation
            q = (float(o.w), float(o.x), float(o.y), float(o.z))
            vb = (float(lin.x), float(lin.y), float(lin.z))
        else:
            return "malformed"
    except Exception:  # noqa: BLE001 - malformed: counted, never raised
        return "malformed"
    if t_ns == 0:
        return "stamp"
    if expected_frame_id and frame != expected_frame_id:
        return "frame"
    if kind == "odometry":
        n = math.sqrt(sum(c * c for c in q))
        if not (math.isfinite(n) and abs(n - 1.0) < 0.1):
            return "nonfinite" if not math.isfinite(n) else "frame"
        w, x, y, z = (c / n for c in q)
        bx, by, bz = vb
        tx, ty, tz = 2.0 * (y * bz - z * by), 2.0 * (z * bx - x * bz), 2.0 * (x * by - y * bx)
        v = (bx + w * tx + y * tz - z * ty, by + w * ty + z * tx - x * tz,
             bz + w * tz + x * ty - y * tx)
    if not math.isfinite(v[0] + v[1] + v[2]):
        return "nonfinite"
    if velocity_frame != world_frame:  # ENU <-> NED: (x, y, z) -> (y, x, -z)
        v = (v[1], v[0], -v[2])
    return t_ns, v
