"""Gravity-free acceleration [m/s²] from the published orientation and specific force.

With ``R`` = R(q_world_from_body) (the published orientation), ``f`` the accelerometer's
specific force in the published body axes and ``g_w`` gravity in the world frame ((0, 0, −g) in
the z-up frames ENU and NWU, (0, 0, +g) in NED):

* world frame: ``a_w = R f + g_w`` (zero at rest);
* body frame:  ``a_b = f + Rᵀ g_w``.

Covariance (3x3 row-major, m²/s⁴). A small attitude error ``δθ`` about the world axes (the
orientation covariance ``P``, rad²) moves ``R f`` by ``δθ × (R f)`` and ``Rᵀ g_w`` by
``Rᵀ [g_w]× δθ``; the accelerometer's own covariance ``Σ_f`` (body axes; unknown = −1 in
element 0: left out) adds: ``C_w = [R f]× P [R f]×ᵀ + R Σ_f Rᵀ``,
``C_b = Rᵀ [g_w]× P [g_w]×ᵀ R + Σ_f``. Before initialisation (``P[0] == -1``) nothing is given.
"""

from __future__ import annotations

from collections.abc import Sequence

Vec3 = tuple[float, float, float]
Mat9 = tuple[float, ...]


def _matrix(q_xyzw: Sequence[float]) -> tuple[Vec3, Vec3, Vec3]:
    x, y, z, w = q_xyzw
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def _mul(a: Sequence[Sequence[float]], b: Sequence[Sequence[float]]) -> list[list[float]]:
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def _t(a: Sequence[Sequence[float]]) -> list[list[float]]:
    return [[a[j][i] for j in range(3)] for i in range(3)]


def _skew(v: Sequence[float]) -> list[list[float]]:
    return [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]]


def _sandwich(m: Sequence[Sequence[float]], c: Sequence[Sequence[float]]) -> list[list[float]]:
    return _mul(_mul(m, c), _t(m))


def _flat(m: Sequence[Sequence[float]]) -> Mat9:
    return tuple(float(m[i][j]) for i in range(3) for j in range(3))


def gravity_free(q_xyzw: Sequence[float], f_body: Sequence[float],
                 orientation_cov: Sequence[float], accel_cov: Sequence[float],
                 gravity_m_s2: float, world_frame: str
                 ) -> tuple[Vec3, Mat9, Vec3, Mat9] | None:
    """``(a_body, cov_body, a_world, cov_world)`` (see the module docstring), or None before
    the filter has an attitude (``orientation_cov[0] == -1``)."""
    if orientation_cov[0] == -1.0:
        return None
    r = _matrix(q_xyzw)
    g_w = (0.0, 0.0, gravity_m_s2 if world_frame == "ned" else -gravity_m_s2)
    rf = tuple(sum(r[i][k] * f_body[k] for k in range(3)) for i in range(3))
    a_w = (rf[0] + g_w[0], rf[1] + g_w[1], rf[2] + g_w[2])
    rtg = tuple(sum(r[k][i] * g_w[k] for k in range(3)) for i in range(3))
    a_b = (f_body[0] + rtg[0], f_body[1] + rtg[1], f_body[2] + rtg[2])
    p = [list(orientation_cov[3 * i:3 * i + 3]) for i in range(3)]
    c_w = _sandwich(_skew(rf), p)
    c_b = _sandwich(_mul(_t(r), _skew(g_w)), p)
    if accel_cov and accel_cov[0] != -1.0:
        s = [list(accel_cov[3 * i:3 * i + 3]) for i in range(3)]
        rs = _sandwich(r, s)
        c_w = [[c_w[i][j] + rs[i][j] for j in range(3)] for i in range(3)]
        c_b = [[c_b[i][j] + s[i][j] for j in range(3)] for i in range(3)]
    return (tuple(map(float, a_b)), _flat(c_b),  # type: ignore[return-value]
            tuple(map(float, a_w)), _flat(c_w))


def accel_covariance6(cov9: Sequence[float]) -> list[float]:
    """The 6x6 row-major covariance of geometry_msgs/AccelWithCovariance: the linear block
    ``cov9``, the angular block -1 on its diagonal (angular acceleration not estimated)."""
    out = [0.0] * 36
    for i in range(3):
        for j in range(3):
            out[6 * i + j] = float(cov9[3 * i + j])
        out[6 * (3 + i) + 3 + i] = -1.0
    return out
