"""Peer estimators from PyPI, each at the settings its authors give, adapted to our conventions.

Every adapter takes SI inputs (gyro rad/s, accelerometer m/s², magnetometer any unit; sensor
frame) and returns q_ENU_from_sensor (w, x, y, z), shape (N, 4) — the same convention as our
filter and the BROAD reference. Units and frames of each peer (see docs/peers.md):

- ``vqf`` (VQF 2.x, online ``VQF`` class via ``updateBatch``, default ``VQFParams``): gyro
  rad/s, acc m/s², mag any; output ``quat6D``/``quat9D`` (w, x, y, z) sensor-to-earth, earth
  ENU for 9-D (heading of the 6-D output arbitrary). Initialises itself.
- ``fusion`` (x-io ``imufusion`` 1.3, set up as its README recommends — the AHRS settings
  table and the gyroscope offset ("bias") module it says to use with the AHRS, as in its
  Python example: :data:`FUSION_SETTINGS`, NWU, gain 0.5, gyroscope range 2000 °/s,
  acceleration and magnetic rejection 10°, rejection timeout (recovery period) 5 s, the sample
  rate set to the recording's; ``Bias`` at its defaults corrects every gyro sample before the
  AHRS update): gyro **deg/s**, acc **g**, mag any; quaternion (w, x, y, z) sensor-to-earth in
  **NWU** → q_ENU = Rz(+90°) ⊗ q. Starts at identity (its 3 s start-up gain ramp).
- ``madgwick`` (``ahrs`` 0.4 ``ahrs.filters.Madgwick``, ported to plain floats and held equal
  to it by a test, at the gain the ROS package
  imu_filter_madgwick ships, ``gain: 0.1``, ``zeta: 0.0`` (no gyro-drift term), the same gain
  for the IMU and MARG updates; ahrs' own defaults, 0.033 IMU / 0.041 MARG, are not what a ROS
  user runs): gyro rad/s, acc and mag any unit (normalised); quaternion (w, x, y, z)
  sensor-to-earth in **NWU** (gravity +z, field in the x–z plane) → q_ENU = Rz(+90°) ⊗ q.
  Its batch mode starts the MARG filter from an NED e-compass quaternion, which does not match
  its own NWU frame (a 180° start error that a small gain takes minutes to remove), so we start
  it as the BROAD example code does: from the first accelerometer (and magnetometer) sample,
  then call its ``updateMARG``/``updateIMU`` per sample (imu_filter_madgwick also starts from
  the first accelerometer and magnetometer sample).
- ``complementary`` (imu_complementary_filter of imu_tools, Valenti, Dryanovski, Xiao,
  "Keeping a Good Attitude", Sensors 15(8), 2015; not on PyPI: :func:`run_complementary` is a
  line-by-line port of its ``ComplementaryFilter`` (CCNYRoboticsLab/imu_tools,
  imu_complementary_filter/src/complementary_filter.cpp) at the defaults its ROS node sets
  (complementary_filter_ros.cpp): ``gain_acc`` 0.01, ``gain_mag`` 0.01, ``bias_alpha`` 0.01,
  ``do_bias_estimation`` true, ``do_adaptive_gain`` true; 9-D whenever a magnetometer sample is
  given (its node's ``use_mag`` defaults to false), the IMU-only update on rows without one, as
  its node does for NaN fields. Gyro rad/s, acc **m/s²** (its steady-state and adaptive-gain
  tests compare |a| with 9.81), mag any unit; state q_sensor_from_world, output its inverse
  q_NWU_from_sensor → q_ENU = Rz(+90°) ⊗ q. Its node uses the first message only to start the
  clock; here the first sample initialises the filter (one sample earlier).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from cf_estimator.core import quaternion as quat
from cf_estimator.core.filter import orientation_from_vectors

STANDARD_GRAVITY = 9.80665
#: q_ENU_from_NWU: a rotation of +90° about z (NWU x = north → ENU y).
Q_ENU_FROM_NWU = np.array([math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])

PEERS = ("vqf", "fusion", "madgwick", "complementary")
#: peer → PyPI package (None: ported here, always available).
PEER_PACKAGES: dict[str, str | None] = {"vqf": "vqf", "fusion": "imufusion", "madgwick": None,
                                        "complementary": None}
#: imu_filter_madgwick's ROS defaults (its ``gain`` and ``zeta`` parameters).
MADGWICK_ROS_GAIN = 0.1
MADGWICK_ROS_ZETA = 0.0


class PeerUnavailable(RuntimeError):
    """The peer's PyPI package is not installed (``pip install .[bench]``)."""


def _require(peer: str):
    module = PEER_PACKAGES[peer]
    if module is None:
        return None
    try:
        return __import__(module)
    except ImportError:
        raise PeerUnavailable(
            f"peer {peer!r} needs the PyPI package {module!r} (pip install '.[bench]')"
        ) from None


def parse_peers(text: str) -> list[str]:
    """``all`` (every peer), ``none`` (no peer) or a comma-separated list → peer names.

    Unknown names raise ValueError naming the valid ones. The one rule of every bench command.
    """
    words = [t.strip() for t in text.split(",") if t.strip()]
    if words in ([], ["none"]):
        return []
    if words == ["all"]:
        return list(PEERS)
    bad = [p for p in words if p not in PEERS]
    if bad:
        raise ValueError(f"unknown peer {bad[0]!r}; valid: {', '.join(PEERS)}, all, none")
    return list(dict.fromkeys(words))


def split_available(peers: list[str]) -> tuple[list[str], list[str]]:
    """(installed peers, peers whose PyPI package is missing), order kept."""
    have, missing = [], []
    for p in peers:
        try:
            _require(p)
        except PeerUnavailable:
            missing.append(p)
        else:
            have.append(p)
    return have, missing


def missing_note(missing: list[str]) -> str:
    """One line naming the skipped peers and how to install them."""
    names = ", ".join(f"{p} (PyPI {PEER_PACKAGES[p]})" for p in missing)  # never a port
    return f"peers not installed, skipped: {names}; pip install '.[bench]' adds them"


def check_available(peers: list[str]) -> None:
    """Raise :class:`PeerUnavailable` for the first peer whose package is missing."""
    for p in peers:
        if p not in PEERS:
            raise ValueError(f"unknown peer {p!r}; valid: {', '.join(PEERS)}")
        _require(p)


def _nan_rows_to_zero(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=float, copy=True)
    out[~np.all(np.isfinite(out), axis=1)] = 0.0
    return out


def run_vqf(gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray | None, rate_hz: float
            ) -> dict[str, np.ndarray]:
    """Online VQF at its defaults; ``{"6d": (N,4), "9d": (N,4), "bias": (N,3)}`` (9d only with
    ``mag``; bias: VQF's gyro-bias estimate [rad/s], sensor frame)."""
    vqf = _require("vqf")
    est = vqf.VQF(1.0 / rate_hz)
    g = np.ascontiguousarray(gyro, dtype=float)
    a = np.ascontiguousarray(acc, dtype=float)
    if mag is None:
        out = est.updateBatch(g, a)
        return {"6d": out["quat6D"], "bias": out["bias"]}
    # VQF ignores zero magnetometer samples (NaN rows would poison its state)
    m = np.ascontiguousarray(_nan_rows_to_zero(mag))
    out = est.updateBatch(g, a, m)
    return {"6d": out["quat6D"], "9d": out["quat9D"], "bias": out["bias"]}


#: x-io Fusion as its README recommends (xioTechnologies/Fusion README, "Algorithm settings":
#: gain 0.5, rejection thresholds 10° and a 5 s recovery period "appropriate for most
#: applications", the gyroscope range "the range specified in the gyroscope datasheet"; its
#: Python example ``complete_example.py`` sets the same values with a 2000 °/s range). The
#: range only arms the over-range restart at 98 % of it: the fastest rotation of any recording
#: here (BROAD, 1446 °/s) stays below it, and below 98 % of each known datasheet range (EuRoC's
#: ADIS16448 ±1000 °/s: 164 °/s flown; the Xsens DOT ±2000 °/s: 365 °/s).
FUSION_SETTINGS = {"convention": "NWU", "gain": 0.5, "gyroscope_range_deg_s": 2000.0,
                   "acceleration_rejection_deg": 10.0, "magnetic_rejection_deg": 10.0,
                   "rejection_timeout_s": 5.0}


def fusion_recommended(rate_hz: float) -> tuple[Any, Any]:
    """(``Ahrs``, its gyroscope offset module ``Bias``) set up as Fusion's README recommends
    (:data:`FUSION_SETTINGS`) for samples at ``rate_hz`` [Hz]: feed each gyro sample [deg/s]
    through ``Bias.update`` before ``Ahrs.update``."""
    imufusion = _require("fusion")
    s = FUSION_SETTINGS
    ahrs = imufusion.Ahrs()
    ahrs.set_settings(imufusion.AhrsSettings(
        sample_rate=float(rate_hz), convention=imufusion.CONVENTION_NWU, gain=s["gain"],
        gyroscope_range=s["gyroscope_range_deg_s"],
        acceleration_rejection=s["acceleration_rejection_deg"],
        magnetic_rejection=s["magnetic_rejection_deg"],
        rejection_timeout=s["rejection_timeout_s"]))
    bias = imufusion.Bias()
    bias.set_settings(imufusion.BiasSettings(sample_rate=float(rate_hz)))
    return ahrs, bias


def run_fusion(gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray | None, rate_hz: float,
               recommended: bool = True) -> np.ndarray:
    """x-io Fusion AHRS (9-D with ``mag``, else ``update_no_magnetometer``).

    ``recommended`` (the bench's peer): :data:`FUSION_SETTINGS` with the sample rate
    ``rate_hz``, and every gyro sample corrected by Fusion's gyroscope offset module (``Bias``,
    its defaults: stationary below 3 °/s for 3 s, then a 0.02 Hz high-pass learns the offset)
    before the AHRS update, as its README and examples pair them. ``False``: ``Ahrs()`` as
    constructed (rejection off: its recovery period is 0; no offset module), only the sample
    period set — the control of the tests that show the recommended set-up at work.
    """
    if recommended:
        ahrs, bias = fusion_recommended(rate_hz)
    else:
        ahrs, bias = _require("fusion").Ahrs(), None
        ahrs.set_sample_period(1.0 / rate_hz)
    g_deg = np.ascontiguousarray(np.degrees(np.asarray(gyro, dtype=float)))
    if bias is not None:  # the offset module sees every sample at the configured rate
        for i in range(g_deg.shape[0]):
            g_deg[i] = bias.update(g_deg[i])
    a_g = np.asarray(acc, dtype=float) / STANDARD_GRAVITY
    n = g_deg.shape[0]
    out = np.empty((n, 4))
    if mag is None:
        upd = ahrs.update_no_magnetometer
        for i in range(n):
            upd(g_deg[i], a_g[i])
            out[i] = ahrs.get_quaternion()
    else:
        m = _nan_rows_to_zero(mag)  # Fusion skips a zero magnetometer vector
        upd9 = ahrs.update
        for i in range(n):
            upd9(g_deg[i], a_g[i], m[i])
            out[i] = ahrs.get_quaternion()
    return quat.multiply(Q_ENU_FROM_NWU, out)


def initial_nwu(acc0: np.ndarray, mag0: np.ndarray | None) -> np.ndarray:
    """q_NWU_from_sensor from one accelerometer (and magnetometer) sample."""
    q_enu = orientation_from_vectors(acc0, mag0)
    return quat.multiply(quat.conjugate(Q_ENU_FROM_NWU), q_enu)


def run_madgwick(gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray | None, rate_hz: float,
                 gain: float = MADGWICK_ROS_GAIN) -> np.ndarray:
    """Madgwick at imu_filter_madgwick's ROS default gain 0.1 (zeta 0), started from the first
    sample: ``ahrs.filters.Madgwick``'s ``updateIMU``/``updateMARG`` (ahrs 0.4), ported to
    plain floats (:func:`madgwick_step`; the same operations, held equal to ahrs sample for
    sample by test/test_fair_peers.py) — ahrs' NumPy per sample costs 100–160 µs, a BROAD
    campaign minutes. Returns q_ENU_from_sensor (N, 4)."""
    g = np.asarray(gyro, dtype=float)
    a = np.asarray(acc, dtype=float)
    n = g.shape[0]
    m = None if mag is None else np.asarray(mag, dtype=float)
    has_mag = (np.zeros(n, dtype=bool) if m is None
               else np.all(np.isfinite(m), axis=1))
    q = tuple(float(c) for c in initial_nwu(a[0], m[0] if has_mag[0] else None))
    out = np.empty((n, 4))
    out[0] = q
    dt = 1.0 / rate_hz
    gl, al = g.tolist(), a.tolist()
    ml = m.tolist() if m is not None else None
    for i in range(1, n):
        q = madgwick_step(q, gl[i], al[i], ml[i] if has_mag[i] else None, gain, dt)
        out[i] = q
    return quat.multiply(Q_ENU_FROM_NWU, out)


def madgwick_step(q: tuple[float, float, float, float], gyr: list[float], acc: list[float],
                   mag: list[float] | None, beta: float, dt: float
                   ) -> tuple[float, float, float, float]:
    """One ``updateMARG`` (``mag`` given, non-zero) or ``updateIMU`` of ahrs' Madgwick
    (its eqs. 12, 25/31, 26/32, 33, 34, 45, 46, 13), NWU, q = q_NWU_from_sensor."""
    qw, qx, qy, qz = q
    nq = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)  # ahrs' Quaternion(q) normalises
    qw, qx, qy, qz = qw / nq, qx / nq, qy / nq, qz / nq
    gx, gy, gz = gyr
    if gx == 0.0 and gy == 0.0 and gz == 0.0:
        return (qw, qx, qy, qz)
    if mag is not None and mag[0] == 0.0 and mag[1] == 0.0 and mag[2] == 0.0:
        mag = None
    # qDot = 0.5 * q ⊗ (0, gyr)
    dw = 0.5 * (-qx * gx - qy * gy - qz * gz)
    dx = 0.5 * (qw * gx + qy * gz - qz * gy)
    dy = 0.5 * (qw * gy - qx * gz + qz * gx)
    dz = 0.5 * (qw * gz + qx * gy - qy * gx)
    ax, ay, az = acc
    an = math.sqrt(ax * ax + ay * ay + az * az)
    if an > 0.0:
        ax, ay, az = ax / an, ay / an, az / an
        f0 = 2.0 * (qx * qz - qw * qy) - ax
        f1 = 2.0 * (qw * qx + qy * qz) - ay
        f2 = 2.0 * (0.5 - qx * qx - qy * qy) - az
        # J^T f of the gravity rows
        sw = -2.0 * qy * f0 + 2.0 * qx * f1
        sx = 2.0 * qz * f0 + 2.0 * qw * f1 - 4.0 * qx * f2
        sy = -2.0 * qw * f0 + 2.0 * qz * f1 - 4.0 * qy * f2
        sz = 2.0 * qx * f0 + 2.0 * qy * f1
        fn2 = f0 * f0 + f1 * f1 + f2 * f2
        if mag is not None:
            mn = math.sqrt(mag[0] * mag[0] + mag[1] * mag[1] + mag[2] * mag[2])
            mx, my, mz = mag[0] / mn, mag[1] / mn, mag[2] / mn
            # h = q ⊗ (0, m) ⊗ q*: the field in the earth frame
            pw = -qx * mx - qy * my - qz * mz
            px = qw * mx + qy * mz - qz * my
            py = qw * my - qx * mz + qz * mx
            pz = qw * mz + qx * my - qy * mx
            hx = -pw * qx + px * qw - py * qz + pz * qy
            hy = -pw * qy + px * qz + py * qw - pz * qx
            hz = -pw * qz - px * qy + py * qx + pz * qw
            bx = math.sqrt(hx * hx + hy * hy)
            bz = hz
            f3 = 2.0 * bx * (0.5 - qy * qy - qz * qz) + 2.0 * bz * (qx * qz - qw * qy) - mx
            f4 = 2.0 * bx * (qx * qy - qw * qz) + 2.0 * bz * (qw * qx + qy * qz) - my
            f5 = 2.0 * bx * (qw * qy + qx * qz) + 2.0 * bz * (0.5 - qx * qx - qy * qy) - mz
            sw += -2.0 * bz * qy * f3 + (-2.0 * bx * qz + 2.0 * bz * qx) * f4 \
                + 2.0 * bx * qy * f5
            sx += 2.0 * bz * qz * f3 + (2.0 * bx * qy + 2.0 * bz * qw) * f4 \
                + (2.0 * bx * qz - 4.0 * bz * qx) * f5
            sy += (-4.0 * bx * qy - 2.0 * bz * qw) * f3 + (2.0 * bx * qx + 2.0 * bz * qz) * f4 \
                + (2.0 * bx * qw - 4.0 * bz * qy) * f5
            sz += (-4.0 * bx * qz + 2.0 * bz * qx) * f3 + (-2.0 * bx * qw + 2.0 * bz * qy) * f4 \
                + 2.0 * bx * qx * f5
            fn2 += f3 * f3 + f4 * f4 + f5 * f5
        if fn2 > 0.0:
            sn = math.sqrt(sw * sw + sx * sx + sy * sy + sz * sz)
            dw -= beta * sw / sn
            dx -= beta * sx / sn
            dy -= beta * sy / sn
            dz -= beta * sz / sn
    qw, qx, qy, qz = qw + dw * dt, qx + dx * dt, qy + dy * dt, qz + dz * dt
    nq = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    return (qw / nq, qx / nq, qy / nq, qz / nq)


# -- imu_complementary_filter (port) ----------------------------------------------------------
#: imu_complementary_filter's ROS defaults (complementary_filter_ros.cpp initializeParams).
COMPLEMENTARY_ROS_DEFAULTS = {"gain_acc": 0.01, "gain_mag": 0.01, "bias_alpha": 0.01,
                              "do_bias_estimation": True, "do_adaptive_gain": True}
_CF_GRAVITY = 9.81  # kGravity
_CF_W_THRESHOLD = 0.2  # kAngularVelocityThreshold [rad/s]
_CF_A_THRESHOLD = 0.1  # kAccelerationThreshold [m/s^2]
_CF_DW_THRESHOLD = 0.01  # kDeltaAngularVelocityThreshold [rad/s]


def _cf_mul(p, q):
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return (p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3, p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1, p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0)


def _cf_norm4(q):
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def _cf_rotate(x, y, z, q0, q1, q2, q3):
    return ((q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) * x + 2 * (q1 * q2 - q0 * q3) * y
            + 2 * (q1 * q3 + q0 * q2) * z,
            2 * (q1 * q2 + q0 * q3) * x + (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * y
            + 2 * (q2 * q3 - q0 * q1) * z,
            2 * (q1 * q3 - q0 * q2) * x + 2 * (q2 * q3 + q0 * q1) * y
            + (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) * z)


def _cf_scale(gain, dq):
    """scaleQuaternion: slerp from identity below dq0 = 0.9, else lerp; normalised."""
    dq0, dq1, dq2, dq3 = dq
    if dq0 <= 0.9:
        angle = math.acos(dq0)
        a = math.sin(angle * (1.0 - gain)) / math.sin(angle)
        b = math.sin(angle * gain) / math.sin(angle)
        out = (a + b * dq0, b * dq1, b * dq2, b * dq3)
    else:
        out = ((1.0 - gain) + gain * dq0, gain * dq1, gain * dq2, gain * dq3)
    return _cf_norm4(out)


def _cf_acc_quat(ax, ay, az):
    """getMeasurement's q_acc from a normalised accelerometer vector."""
    if az >= 0:
        q0 = math.sqrt((az + 1) * 0.5)
        return (q0, -ay / (2.0 * q0), ax / (2.0 * q0), 0.0)
    x = math.sqrt((1 - az) * 0.5)
    return (-ay / (2.0 * x), x, 0.0, ax / (2.0 * x))


def _cf_heading_dq(lx, ly):
    """The delta quaternion about z that turns (lx, ly) onto +x (north)."""
    gamma = lx * lx + ly * ly
    beta = math.sqrt(gamma + lx * math.sqrt(gamma))
    return (beta / math.sqrt(2.0 * gamma), 0.0, 0.0, ly / (math.sqrt(2.0) * beta))


def _cf_unit(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


def run_complementary(gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray | None, rate_hz: float,
                      **overrides: float | bool) -> np.ndarray:
    """imu_complementary_filter (port, see the module docstring) at its ROS defaults
    (``overrides``: gain_acc, gain_mag, bias_alpha, do_bias_estimation, do_adaptive_gain).
    Returns q_ENU_from_sensor (N, 4)."""
    cfg = {**COMPLEMENTARY_ROS_DEFAULTS, **overrides}
    gain_acc, gain_mag, bias_alpha = cfg["gain_acc"], cfg["gain_mag"], cfg["bias_alpha"]
    do_bias, adaptive = bool(cfg["do_bias_estimation"]), bool(cfg["do_adaptive_gain"])
    g = np.asarray(gyro, dtype=float).tolist()
    a = np.asarray(acc, dtype=float).tolist()
    m = None if mag is None else np.asarray(mag, dtype=float).tolist()
    dt = 1.0 / rate_hz
    n = len(g)
    out = np.empty((n, 4))
    q = (1.0, 0.0, 0.0, 0.0)  # state: q_sensor_from_world (fixed wrt the body)
    bx = by = bz = 0.0
    wpx = wpy = wpz = 0.0
    initialized = False
    for i in range(n):
        ax, ay, az = a[i]
        wx, wy, wz = g[i]
        mi = m[i] if m is not None else None
        has_mag = mi is not None and all(math.isfinite(c) for c in mi)
        if not initialized:
            qa = _cf_acc_quat(*_cf_unit(ax, ay, az))
            if has_mag:
                mx, my, mz = mi
                q0a, q1a, q2a, _q3a = qa
                lx = ((q0a * q0a + q1a * q1a - q2a * q2a) * mx + 2.0 * (q1a * q2a) * my
                      - 2.0 * (q0a * q2a) * mz)
                ly = (2.0 * (q1a * q2a) * mx + (q0a * q0a - q1a * q1a + q2a * q2a) * my
                      + 2.0 * (q0a * q1a) * mz)
                q = _cf_mul(qa, _cf_heading_dq(lx, ly))
            else:
                q = qa
            initialized = True
        else:
            if do_bias:  # updateBiases / checkState
                steady = (abs(math.sqrt(ax * ax + ay * ay + az * az) - _CF_GRAVITY)
                          <= _CF_A_THRESHOLD
                          and abs(wx - wpx) <= _CF_DW_THRESHOLD
                          and abs(wy - wpy) <= _CF_DW_THRESHOLD
                          and abs(wz - wpz) <= _CF_DW_THRESHOLD
                          and abs(wx - bx) <= _CF_W_THRESHOLD
                          and abs(wy - by) <= _CF_W_THRESHOLD
                          and abs(wz - bz) <= _CF_W_THRESHOLD)
                if steady:
                    bx += bias_alpha * (wx - bx)
                    by += bias_alpha * (wy - by)
                    bz += bias_alpha * (wz - bz)
                wpx, wpy, wpz = wx, wy, wz
            # getPrediction
            ux, uy, uz = wx - bx, wy - by, wz - bz
            q0, q1, q2, q3 = q
            pred = _cf_norm4((q0 + 0.5 * dt * (ux * q1 + uy * q2 + uz * q3),
                              q1 + 0.5 * dt * (-ux * q0 - uy * q3 + uz * q2),
                              q2 + 0.5 * dt * (ux * q3 - uy * q0 - uz * q1),
                              q3 + 0.5 * dt * (-ux * q2 + uy * q1 - uz * q0)))
            # getAccCorrection
            nx, ny, nz = _cf_unit(ax, ay, az)
            p0, p1, p2, p3 = pred
            gx, gy, gz = _cf_rotate(nx, ny, nz, p0, -p1, -p2, -p3)
            dq0 = math.sqrt((gz + 1) * 0.5)
            dq = (dq0, -gy / (2.0 * dq0), gx / (2.0 * dq0), 0.0)
            alpha = gain_acc
            if adaptive:  # getAdaptiveGain
                err = abs(math.sqrt(ax * ax + ay * ay + az * az) - _CF_GRAVITY) / _CF_GRAVITY
                factor = 1.0 if err < 0.1 else ((-10.0 * err + 2.0) if err < 0.2 else 0.0)
                alpha = factor * gain_acc
            q = _cf_mul(pred, _cf_scale(alpha, dq))
            if has_mag:  # getMagCorrection
                t0, t1, t2, t3 = q
                lx, ly, _lz = _cf_rotate(mi[0], mi[1], mi[2], t0, -t1, -t2, -t3)
                q = _cf_mul(q, _cf_scale(gain_mag, _cf_heading_dq(lx, ly)))
            q = _cf_norm4(q)
        out[i] = (q[0], -q[1], -q[2], -q[3])  # getOrientation: the inverse of the state
    return quat.multiply(Q_ENU_FROM_NWU, out)


def runners() -> dict[str, Callable[..., dict[str, np.ndarray]]]:
    """peer → f(gyro, acc, mag, rate_hz, dims) → {"9d": q, "6d": q} for the dims asked."""

    def vqf(g, a, m, r, dims):
        out = run_vqf(g, a, m if "9d" in dims else None, r)
        return {d: out[d] for d in dims if d in out}

    def single(fn):
        def run(g, a, m, r, dims):
            res = {}
            if "9d" in dims:
                res["9d"] = fn(g, a, m, r)
            if "6d" in dims:
                res["6d"] = fn(g, a, None, r)
            return res
        return run

    return {"vqf": vqf, "fusion": single(run_fusion), "madgwick": single(run_madgwick),
            "complementary": single(run_complementary)}


def run_vqf_offline(gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray | None, rate_hz: float
                    ) -> dict[str, np.ndarray]:
    """Offline (acausal, whole-recording) VQF at its defaults (``vqf.offlineVQF``); same frames
    and outputs as :func:`run_vqf`."""
    vqf = _require("vqf")
    g = np.ascontiguousarray(gyro, dtype=float)
    a = np.ascontiguousarray(acc, dtype=float)
    m = None if mag is None else np.ascontiguousarray(_nan_rows_to_zero(mag))
    out = vqf.offlineVQF(g, a, m, 1.0 / rate_hz)
    return {"6d": out["quat6D"]} if m is None else {"6d": out["quat6D"], "9d": out["quat9D"]}


def run_riann(gyro: np.ndarray, acc: np.ndarray, rate_hz: float) -> np.ndarray:
    """RIANN (PyPI ``riann``: a recurrent network on ONNX Runtime with its shipped weights;
    Weber, Gühmann, Seel, AI 2(3), 2021), 6-D only, over the whole recording at once.

    Inputs acc m/s², gyro rad/s, and the sample period; output (w, x, y, z) sensor-to-earth with
    the earth z axis up (its heading is arbitrary), float32 → normalised float64. The weights are
    passed by path: riann 0.2.0 cannot locate its own file on Python 3.11 (it asks
    ``importlib.resources.path`` for a module, not a package).
    """
    try:
        import importlib.resources

        from riann import RIANN
    except ImportError:
        raise PeerUnavailable(
            "peer 'riann' needs the PyPI package 'riann' (pip install '.[bench]')") from None
    model = RIANN(str(importlib.resources.files("riann") / "riann.onnx"))
    q = np.asarray(model.predict(np.asarray(acc, dtype=float), np.asarray(gyro, dtype=float),
                                 float(rate_hz)), dtype=float)
    return q / np.linalg.norm(q, axis=1, keepdims=True)
