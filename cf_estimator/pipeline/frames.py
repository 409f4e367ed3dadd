"""Output frames: the world frame published (enu, ned, nwu), true north, and honest frame ids.

The core filters estimate in ENU or NED (:data:`CORE_WORLD_FRAMES`). The pipeline publishes
in ``world_frame`` (:data:`WORLD_FRAMES`: also NWU, as imu_filter_madgwick offers) with the
magnetic declination and a yaw offset applied, as one fixed rotation on the left of the
core's orientation (:class:`OutputFrame`):

    q_out = C ⊗ R_z(θ) ⊗ q_core

``C`` turns the core's world into the published one (identity, or NWU from ENU: a quarter
turn about z); ``θ`` [rad] turns magnetic north into true north and adds the yaw offset:
``θ = -declination + yaw_offset`` about ENU's up axis, ``θ = +declination + yaw_offset`` about
NED's down axis, so that in every world frame the published yaw is the true-north yaw plus
``yaw_offset_rad`` (declination east positive, as the World Magnetic Model gives it: a body
pointing at magnetic north has a true heading of +declination). Rotations about the vertical
leave ``orientation_covariance``'s diagonal (tilt, tilt, yaw) as it is.

Frame ids (:func:`output_frame_id`, :func:`check_tf_frames`): an output whose body axes differ
from the input's (``body_frame`` FLU in NED: FRD, or FRD in ENU/NWU: FLU) is published under a
frame id that says so (``<input>_frd``, ``<input>_flu``, MAVROS' naming: base_link_frd) unless
``output_frame_id`` names one; a TF parent in a world frame other than REP-103's ENU must be
named for it (``*_ned``, ``*_nwu``: MAVROS' map_ned, odom_ned), or the node refuses to start.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

#: World frames the pipeline publishes in.
WORLD_FRAMES = ("enu", "ned", "nwu")
#: World frames the core filters estimate in.
CORE_WORLD_FRAMES = ("enu", "ned")
#: ``output_frame_id`` value: derive the frame id from the input's (see :func:`output_frame_id`).
AUTO = "auto"
_S = math.sqrt(0.5)
#: q_nwu_from_enu (w, x, y, z): a quarter turn about z (east → -y, north → x).
Q_NWU_FROM_ENU = (_S, 0.0, 0.0, -_S)


def core_world_frame(world_frame: str) -> str:
    """The core's world frame for a published ``world_frame`` (NWU is estimated in ENU)."""
    return "enu" if world_frame == "nwu" else world_frame


def core_params(params: Any) -> Any:
    """``params`` (FilterParams) with ``world_frame`` the core's (a copy only when it differs)."""
    frame = core_world_frame(params.world_frame)
    if frame == params.world_frame:
        return params
    return dataclasses.replace(params, world_frame=frame)


def body_convention(world_frame: str, body_frame: str) -> str:
    """The body axes of the published orientation: ``flu``/``frd`` (paired with the world:
    FRD in NED, FLU in ENU and NWU), or ``sensor`` (the message axes as they are)."""
    if body_frame == "sensor":
        return "sensor"
    return "frd" if world_frame == "ned" else "flu"


def _mul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


class OutputFrame:
    """The fixed rotation from the core's world frame to the published one (module docstring).

    ``world_frame``: published frame (enu, ned, nwu); ``declination_rad`` [rad], east
    positive; ``yaw_offset_rad`` [rad], added to the published yaw. :attr:`identity` is True
    when nothing is to be done (ENU/NED without declination or offset): callers skip it, so
    such outputs are bit-identical to the core's.
    """

    def __init__(self, world_frame: str, declination_rad: float = 0.0,
                 yaw_offset_rad: float = 0.0) -> None:
        if world_frame not in WORLD_FRAMES:
            raise ValueError(f"world_frame {world_frame!r} is not one of {WORLD_FRAMES}")
        core = core_world_frame(world_frame)
        theta = (declination_rad if core == "ned" else -declination_rad) + yaw_offset_rad
        rz = (math.cos(0.5 * theta), 0.0, 0.0, math.sin(0.5 * theta))
        c = Q_NWU_FROM_ENU if world_frame == "nwu" else (1.0, 0.0, 0.0, 0.0)
        self.q = _mul(c, rz)  #: (w, x, y, z) applied on the left
        self.identity = world_frame != "nwu" and theta == 0.0

    def apply_array(self, q_wxyz: np.ndarray) -> np.ndarray:
        """q_out (w, x, y, z) of the core's q (w, x, y, z), row by row of an (N, 4) array (NaN
        rows stay NaN)."""
        if self.identity:
            return q_wxyz
        from cf_estimator.core import quaternion as quat

        return quat.multiply(np.asarray(self.q), q_wxyz)


def suffix_for(convention: str) -> str:
    """``_frd`` / ``_flu``: the frame-id suffix of a body convention."""
    return f"_{convention}"


def converts_body(world_frame: str, body_frame: str) -> bool:
    """Whether the published body axes differ from the input's (the pipeline's half turn)."""
    return body_frame != "sensor" and body_frame != body_convention(world_frame, body_frame)


def output_frame_id(input_frame_id: str, setting: str, world_frame: str,
                    body_frame: str) -> str:
    """The frame id of imu/data, imu/rpy and the TF child.

    ``setting`` (``output_frame_id``): a frame id, used as given; ``auto``: the input's, with
    ``_frd``/``_flu`` added when the published body axes are not the input's (FLU input in
    NED: ``base_link`` → ``base_link_frd``; an input already named so keeps its name), so a
    REP-103 reader never takes an FRD orientation for its FLU frame.
    """
    if setting != AUTO:
        return setting
    if not converts_body(world_frame, body_frame):
        return input_frame_id
    suffix = suffix_for(body_convention(world_frame, body_frame))
    if not input_frame_id or input_frame_id.endswith(suffix):
        return input_frame_id
    other = suffix_for(body_frame)
    base = input_frame_id[: -len(other)] if input_frame_id.endswith(other) else input_frame_id
    return base + suffix


def check_tf_frames(world_frame: str, body_frame: str, tf_parent_frame: str,
                    setting: str) -> tuple[str | None, str | None]:
    """``(refusal, warning)`` for the TF this configuration would broadcast (None: fine).

    Refused: a parent frame in NED/NWU not named for it (``world`` or ``map`` are REP-103 ENU
    to every ROS consumer: the transform would be misread); an explicit ``output_frame_id`` for
    an FRD/FLU-converted body that does not end in the published convention's suffix. Warned:
    ``body_frame: sensor`` with a NED/NWU parent (the child's axes are whatever the driver's).
    """
    suffix = f"_{world_frame}"
    if world_frame != "enu" and not tf_parent_frame.endswith(suffix):
        return (f"publish_tf with world_frame {world_frame}: tf_parent_frame "
                f"'{tf_parent_frame}' would be read as a REP-103 (ENU) frame; name it for its "
                f"convention, e.g. tf_parent_frame:={tf_parent_frame.rsplit('_', 1)[0]}{suffix} "
                "(MAVROS: map_ned, odom_ned), or publish in world_frame enu", None)
    if setting != AUTO and converts_body(world_frame, body_frame):
        conv = body_convention(world_frame, body_frame)
        if not setting.endswith(suffix_for(conv)):
            return (f"publish_tf: output_frame_id '{setting}' would carry an "
                    f"{conv.upper()} body (body_frame {body_frame} in {world_frame}) under a "
                    f"name without '{suffix_for(conv)}'; use e.g. {setting}{suffix_for(conv)} "
                    "or output_frame_id:=auto", None)
    if world_frame != "enu" and body_frame == "sensor":
        return None, (f"publish_tf with world_frame {world_frame} and body_frame sensor: the "
                      "child frame has the driver's axes; set body_frame (flu or frd) so the "
                      "transform says which")
    return None, None
