"""Peer estimators from PyPI at their defaults, each adapted to our conventions.

Every adapter takes SI inputs (gyro rad/s, accelerometer m/s², magnetometer any unit; sensor
frame) and returns q_ENU_from_sensor (w, x, y, z), shape (N, 4) — the same convention as our
filter and the BROAD reference. Units and frames of each peer (see docs/peers.md):

- ``vqf`` (VQF 2.x, online ``VQF`` class via ``updateBatch``, default ``VQFParams``): gyro
  rad/s, acc m/s², mag any; output ``quat6D``/``quat9D`` (w, x, y, z) sensor-to-earth, earth
  ENU for 9-D (heading of the 6-D output arbitrary). Initialises itself.
- ``fusion`` (x-io ``imufusion`` 1.3, ``Ahrs`` at its default settings: NWU, gain 0.5,
  3 s start-up gain ramp, rejection off since the recovery period is 0): gyro **deg/s**, acc
  **g**, mag any; quaternion (w, x, y, z) sensor-to-earth in **NWU** → q_ENU = Rz(+90°) ⊗ q.
  The sample period is set to 1/rate (its default assumes 100 Hz). Starts at identity.
- ``madgwick`` (``ahrs`` 0.4 ``ahrs.filters.Madgwick``, default gains 0.041 MARG / 0.033 IMU):
  gyro rad/s, acc and mag any unit (normalised); quaternion (w, x, y, z) sensor-to-earth in
  **NWU** (gravity +z, field in the x–z plane) → q_ENU = Rz(+90°) ⊗ q. Its batch mode starts
  the MARG filter from an NED e-compass quaternion, which does not match its own NWU frame
  (a 180° start error that gain 0.041 takes about a minute to remove), so we start it as the
  BROAD example code does: from the first accelerometer (and magnetometer) sample, then call
  its ``updateMARG``/``updateIMU`` per sample.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from cf_estimator.core import quaternion as quat
from cf_estimator.core.filter import orientation_from_vectors

STANDARD_GRAVITY = 9.80665
#: q_ENU_from_NWU: a rotation of +90° about z (NWU x = north → ENU y).
Q_ENU_FROM_NWU = np.array([math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])

PEERS = ("vqf", "fusion", "madgwick")
PEER_PACKAGES = {"vqf": "vqf", "fusion": "imufusion", "madgwick": "ahrs"}


class PeerUnavailable(RuntimeError):
    """The peer's PyPI package is not installed (``pip install .[bench]``)."""


def _require(peer: str):
    module = PEER_PACKAGES[peer]
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
    names = ", ".join(f"{p} (PyPI {PEER_PACKAGES[p]})" for p in missing)
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
    """Online VQF at its defaults; ``{"6d": (N,4), "9d": (N,4)}`` (9d only with ``mag``)."""
    vqf = _require("vqf")
    est = vqf.VQF(1.0 / rate_hz)
    g = np.ascontiguousarray(gyro, dtype=float)
    a = np.ascontiguousarray(acc, dtype=float)
    if mag is None:
        out = est.updateBatch(g, a)
        return {"6d": out["quat6D"]}
    # VQF ignores zero magnetometer samples (NaN rows would poison its state)
    m = np.ascontiguousarray(_nan_rows_to_zero(mag))
    out = est.updateBatch(g, a, m)
    return {"6d": out["quat6D"], "9d": out["quat9D"]}


def run_fusion(gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray | None, rate_hz: float
               ) -> np.ndarray:
    """x-io Fusion AHRS at its defaults (9-D with ``mag``, else ``update_no_magnetometer``)."""
    imufusion = _require("fusion")
    ahrs = imufusion.Ahrs()
    ahrs.set_sample_period(1.0 / rate_hz)
    g_deg = np.degrees(np.asarray(gyro, dtype=float))
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


def run_madgwick(gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray | None, rate_hz: float
                 ) -> np.ndarray:
    """Madgwick (``ahrs`` package) at its default gains, started from the first sample."""
    _require("madgwick")
    from ahrs.filters import Madgwick

    g = np.asarray(gyro, dtype=float)
    a = np.asarray(acc, dtype=float)
    n = g.shape[0]
    m = None if mag is None else np.asarray(mag, dtype=float)
    filt = Madgwick(frequency=rate_hz) if m is None else Madgwick(frequency=rate_hz, gain=0.041)
    # the default gain is chosen from the presence of mag at construction: set it explicitly
    filt.gain = filt.gain_imu if m is None else filt.gain_marg
    first_mag = m[0] if m is not None and np.all(np.isfinite(m[0])) else None
    q = initial_nwu(a[0], first_mag)
    out = np.empty((n, 4))
    out[0] = q
    for i in range(1, n):
        if m is not None and np.all(np.isfinite(m[i])):
            q = filt.updateMARG(q, g[i], a[i], m[i])
        else:
            q = filt.updateIMU(q, g[i], a[i])
        out[i] = q
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

    return {"vqf": vqf, "fusion": single(run_fusion), "madgwick": single(run_madgwick)}


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
