"""What an IMU-only filter can know on a multirotor in sustained acceleration (issue 22).

The accelerometer measures the specific force ``a − g``. A filter that takes its direction as
"up" is off the vertical by ``atan(|a_h|/g)`` while the vehicle accelerates horizontally by
``a_h`` [m/s²] — on a multirotor that is most of the time, since it accelerates by tilting its
thrust axis, which the accelerometer then reads. No IMU-only filter can separate the two; it can
only average. A filter whose memory (accelerometer averaging) is ``T`` [s], with a perfect gyro,
is off the vertical by the vehicle's *mean* horizontal acceleration over its memory::

    e_acc(T) = atan(|v_h(t) − v_h(t − T)| / (g·T))        [rad]

(exactly, for a moving average; about, for the filter's exponential memory). A long memory
averages a zig-zag out, but the gyro has to carry the attitude over it: a bias residual δb
[rad/s] — what an in-flight start has not learned yet — tilts the estimate by about δb·T/2
on average over the memory, and the bias can only be learned from the same accelerometer.
Velocity aiding removes ``e_acc`` altogether: with the velocity known, ``a_h`` is known and
taken out of the specific force (what is left is the velocity noise, σ_v·√2/(g·T)).

:func:`analyse` computes these floors from each recording's reference velocity (world ENU,
m/s), fits the one term by which an IMU alone sees the velocity — the rotor drag across the
thrust axis (:func:`rotor_drag`) — and scores ours online, ours velocity-aided and VQF online
on the same samples; the
numbers are ``cf-estimator bench sustained``'s (BENCHMARKS.md, "Sustained acceleration"), the
figure :func:`plot`'s (docs/img/sustained_acceleration.png).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from cf_estimator import metrics
from cf_estimator.bench.euroc import Flight
from cf_estimator.bench.euroc_eval import SETTLE_S, VelocityInput, aided_algorithms
from cf_estimator.core import quaternion as quat
from cf_estimator.core.batch import estimate
from cf_estimator.core.params import FilterParams
from cf_estimator.scenarios.motion import DRAG_PER_S

#: Memories T [s] of the floor table (0.5 s: about the accelerometer's own disagreement).
MEMORIES_S = (0.5, 1.0, 2.0, 5.0, 10.0)
#: Name of ours online among :func:`estimators`.
OURS = "cf_estimator"
#: The scored samples split at this time [s]: the first seconds after the settling, while an
#: in-air start is still learning its bias, and the rest.
SPLIT_S = 20.0
#: Gyro-bias residual [deg/s] for the drift column: about what an in-flight start has left
#: after 10 s on the Phantom 4 (BENCHMARKS.md, issue 22).
BIAS_RESIDUAL_DEG_S = 0.5
GRAVITY_M_S2 = 9.80665
#: Averaging [s] of the specific force in the rotor-drag fit: rotor vibration out, the
#: vehicle's velocity changes (seconds) kept.
DRAG_AVERAGING_S = 1.0


def mean_acceleration_tilt_deg(flight: Flight, memory_s: float) -> np.ndarray:
    """Per IMU sample: ``atan(|v_h(t) − v_h(t − T)|/(g·T))`` [deg], the tilt a perfect-gyro
    filter averaging the accelerometer over ``memory_s`` = T [s] cannot avoid (NaN before
    the reference velocity covers ``t − T``)."""
    if flight.velocity_t_s is None or flight.velocity_m_s is None:
        raise ValueError(f"{flight.name}: no reference velocity")
    tv, v = flight.velocity_t_s, flight.velocity_m_s
    t = flight.t_s
    now = np.stack([np.interp(t, tv, v[:, i]) for i in range(2)], axis=1)
    then = np.stack([np.interp(t - memory_s, tv, v[:, i]) for i in range(2)], axis=1)
    dv = np.linalg.norm(now - then, axis=1)
    out = np.degrees(np.arctan2(dv, GRAVITY_M_S2 * memory_s))
    out[(t - memory_s < tv[0]) | (t > tv[-1])] = np.nan
    return out


def reference_bias_rad_s(flight: Flight) -> np.ndarray:
    """The gyro's bias (3,) [rad/s, sensor frame] the reference shows: the median over the
    recording of gyro − the reference's rate (from consecutive reference quaternions)."""
    q = flight.q_ref
    w1, x1, y1, z1 = q[:-1, 0], -q[:-1, 1], -q[:-1, 2], -q[:-1, 3]  # conjugate of q[i]
    w2, x2, y2, z2 = q[1:, 0], q[1:, 1], q[1:, 2], q[1:, 3]
    dw = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    d = np.stack([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                  w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=1)
    rate = 2.0 * d * np.sign(dw)[:, None] / np.diff(flight.t_s)[:, None]
    ok = np.all(np.isfinite(rate), axis=1)
    return np.median(flight.gyro_rad_s[:-1][ok] - rate[ok], axis=0)


@dataclass(frozen=True)
class RotorDrag:
    """The rotor-drag model fitted to one recording (:func:`rotor_drag`)."""

    k_per_s: float  #: K [1/s]: the specific force across the thrust axis is −K·v (+ const)
    explained: float  #: share [1] of that force's variance the model explains (R²)
    #: RMS per axis [m/s] of the model's residual over K: the error of the velocity it implies
    velocity_error_m_s: float
    #: RMS per axis [m/s] of the velocity across the thrust axis about its mean: its swing
    velocity_swing_m_s: float


def _moving_mean(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving mean over ``n`` rows of ``x`` (N, 3); NaN where the window is cut or
    holds a non-finite row."""
    finite = np.all(np.isfinite(x), axis=1)
    c = np.concatenate((np.zeros((1, x.shape[1])), np.cumsum(np.where(finite[:, None], x, 0.0),
                                                             axis=0)))
    count = np.concatenate(([0], np.cumsum(finite)))
    out = np.full_like(x, np.nan)
    half = n // 2
    whole = (count[n:] - count[:-n]) == n
    out[half:x.shape[0] - n + half + 1] = np.where(whole[:, None], (c[n:] - c[:-n]) / n, np.nan)
    return out


def rotor_drag(flight: Flight) -> RotorDrag:
    """Fit f_⊥ = −K·v_⊥ + c on a recording with a reference attitude and velocity.

    A multirotor's rotors push along its thrust axis, and its accelerometer reads that thrust
    plus the rotor (and body) drag, about −K·v across the axis for the air-relative velocity
    v [m/s, sensor frame]: the one term by which an IMU alone sees the vehicle's velocity,
    hence its acceleration and its tilt. Fitted here: the specific force averaged over
    DRAG_AVERAGING_S (vibration out), the reference's velocity averaged alike and turned into the
    sensor frame by the reference's attitude, both across the recording's mean thrust axis
    (the mean specific force's direction) and about their means (the constant c: a steady
    wind × K, the accelerometer's bias, the mounting), K by least squares (isotropic across
    the axis)."""
    if flight.velocity_t_s is None or flight.velocity_m_s is None:
        raise ValueError(f"{flight.name}: no reference velocity")
    t, tv, vw = flight.t_s, flight.velocity_t_s, flight.velocity_m_s
    n_mean = max(1, round(flight.rate_hz * DRAG_AVERAGING_S))
    force = _moving_mean(flight.accel_m_s2, n_mean)
    v_world = np.stack([np.interp(t, tv, vw[:, i]) for i in range(3)], axis=1)
    v_world[(t < tv[0]) | (t > tv[-1])] = np.nan
    # averaged as the force is, then into the sensor frame (NaN without a reference)
    v_all = quat.rotate(quat.conjugate(flight.q_ref), _moving_mean(v_world, n_mean))
    ok = np.all(np.isfinite(force), axis=1) & np.all(np.isfinite(v_all), axis=1)
    if np.count_nonzero(ok) < 3:
        raise ValueError(f"{flight.name}: too few samples with a reference for the drag fit")
    f, v = force[ok], v_all[ok]
    axis = np.mean(f, axis=0)
    axis /= np.linalg.norm(axis)
    f_across = f - np.outer(f @ axis, axis)
    v_across = v - np.outer(v @ axis, axis)
    f_across -= f_across.mean(axis=0)
    v_across -= v_across.mean(axis=0)
    vv = float(np.sum(v_across * v_across))
    k = -float(np.sum(f_across * v_across)) / vv if vv > 0.0 else math.nan
    residual = f_across + k * v_across
    rr = float(np.sum(residual * residual))
    ff = float(np.sum(f_across * f_across))
    n = f_across.shape[0]
    return RotorDrag(k, 1.0 - rr / ff if ff > 0.0 else math.nan,
                     math.sqrt(rr / (2 * n)) / k if k > 0.0 else math.inf,
                     math.sqrt(vv / (2 * n)))


def learned_bias_error_deg_s(flight: Flight, bias_rad_s: np.ndarray, at_s: float = SETTLE_S
                             ) -> float:
    """|b − b_ref| [deg/s] at ``at_s`` [s] of a bias series ``bias_rad_s`` (N, 3) [rad/s] on
    the flight's samples (ours online: ``EstimateResult.gyro_bias_rad_s``; b_ref:
    :func:`reference_bias_rad_s`; beyond the recording: its last sample)."""
    i = min(int(np.searchsorted(flight.t_s, at_s)), flight.n_samples - 1)
    return math.degrees(float(np.linalg.norm(bias_rad_s[i] - reference_bias_rad_s(flight))))


@dataclass(frozen=True)
class FamilyFloors:
    """One family's figures [deg, RMS after SETTLE_S, mean over recordings]."""

    family: str
    n: int
    median_horizontal_accel_m_s2: float
    floor_deg: dict[float, float]  # memory T [s] -> e_acc(T)
    measured_deg: dict[str, float]  # estimator -> inclination error
    #: estimator -> (RMS over SETTLE_S..SPLIT_S, RMS after SPLIT_S) [deg], means over recordings
    #: (recordings shorter than SPLIT_S count in the first only)
    measured_split_deg: dict[str, tuple[float, float]]
    reference_bias_deg_s: float  # |b_ref|, the bias the reference shows
    bias_error_deg_s: float  # |b − b_ref| of ours online at SETTLE_S
    bias_error_end_deg_s: float  # |b − b_ref| of ours online at the last sample
    #: |b − b_ref| of VQF online's own bias estimate at SETTLE_S and at the last sample [deg/s]
    #: (NaN without VQF)
    vqf_bias_error_deg_s: tuple[float, float] = (math.nan, math.nan)
    #: the rotor-drag fit (:func:`rotor_drag`), each figure the median over recordings
    rotor_drag: RotorDrag | None = None


def _rms(x: np.ndarray, mask: np.ndarray) -> float:
    m = mask & np.isfinite(x)
    return float(np.sqrt(np.mean(x[m] ** 2))) if m.any() else math.nan


def with_known_bias(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, t_s: np.ndarray,
                    bias_rad_s: np.ndarray, params: FilterParams) -> np.ndarray:
    """Ours online, 6-D, with a known gyro bias ``bias_rad_s`` [rad/s, sensor; (3,) or one row
    per sample] taken out of the gyro and no bias learning (integral, in-flight raise, rest):
    what the loop would do if its bias learning were perfect. An analysis (of recordings with
    a reference, of simulations with a truth), never a filter mode. → q_world_from_sensor (N, 4)."""
    p = dataclasses.replace(params, use_mag=False, k2=0.0, bias_learning_k2=0.0,
                            rest_bias_learning=False)
    return estimate(gyro_rad_s - bias_rad_s, accel_m_s2, None, timestamps_s=t_s,
                    params=p).quaternion


def with_reference_bias(flight: Flight, params: FilterParams) -> np.ndarray:
    """:func:`with_known_bias` with the bias the reference shows (:func:`reference_bias_rad_s`):
    the reference is not there in flight. → q_world_from_sensor (N, 4)."""
    return with_known_bias(flight.gyro_rad_s, flight.accel_m_s2, flight.t_s,
                           reference_bias_rad_s(flight), params)


def estimators(params: FilterParams, with_vqf: bool) -> dict[str, Callable[[Flight], np.ndarray]]:
    """Name → f(flight) → q_world_from_sensor (N, 4): ours online, ours with the reference's
    bias (:func:`with_reference_bias`), ours aided, VQF online."""
    p = dataclasses.replace(params, use_mag=False)
    aided = aided_algorithms(VelocityInput())[0]
    out: dict[str, Callable[[Flight], np.ndarray]] = {
        OURS: lambda f: estimate(f.gyro_rad_s, f.accel_m_s2, None, timestamps_s=f.t_s,
                                 params=p).quaternion,
        "cf_estimator_reference_bias": lambda f: with_reference_bias(f, params),
        "cf_estimator_aided": lambda f: aided.run(f, p),
    }
    if with_vqf:
        out["vqf"] = lambda f: _run_vqf(f)["6d"]
    return out


def _run_vqf(flight: Flight) -> dict[str, np.ndarray]:
    """VQF online, 6-D, at the flight's median rate: {"6d": q (N, 4), "bias": (N, 3) [rad/s]}."""
    from cf_estimator.bench.peers import run_vqf

    return run_vqf(flight.gyro_rad_s, flight.accel_m_s2, None,
                   1.0 / float(np.median(np.diff(flight.t_s))))


def analyse(family: str, flights: Sequence[Flight], params: FilterParams,
            with_vqf: bool = True) -> FamilyFloors:
    """The floors e_acc(T) for :data:`MEMORIES_S` and the measured inclination errors, each
    the mean over ``flights`` of its RMS over the scored samples (t ≥ SETTLE_S, reference);
    the reference's gyro bias and ours' (and VQF online's) learned-bias error at SETTLE_S and
    at the end, means over ``flights``."""
    flights = [f for f in flights if f.velocity_t_s is not None]
    if not flights:
        raise ValueError(f"{family}: no recording with a reference velocity")
    runs = estimators(params, with_vqf)
    floors: dict[float, list[float]] = {t: [] for t in MEMORIES_S}
    measured: dict[str, list[float]] = {k: [] for k in runs}
    split: dict[str, tuple[list[float], list[float]]] = {k: ([], []) for k in runs}
    accel, bias_ref, bias_err, bias_err_end = [], [], [], []
    vqf_err: list[tuple[float, float]] = []
    drags: list[RotorDrag] = []
    p = dataclasses.replace(params, use_mag=False)
    for f in flights:
        drags.append(rotor_drag(f))
        # ours online once: its attitude is a measured row, its bias the learned-bias rows
        ours = estimate(f.gyro_rad_s, f.accel_m_s2, None, timestamps_s=f.t_s, params=p)
        bias_ref.append(math.degrees(float(np.linalg.norm(reference_bias_rad_s(f)))))
        bias_err.append(learned_bias_error_deg_s(f, ours.gyro_bias_rad_s))
        bias_err_end.append(learned_bias_error_deg_s(f, ours.gyro_bias_rad_s, at_s=math.inf))
        vqf = _run_vqf(f) if with_vqf else None
        if vqf is not None:
            vqf_err.append((learned_bias_error_deg_s(f, vqf["bias"]),
                            learned_bias_error_deg_s(f, vqf["bias"], at_s=math.inf)))
        mask = (f.t_s >= SETTLE_S) & f.has_reference
        for t in MEMORIES_S:
            floors[t].append(_rms(mean_acceleration_tilt_deg(f, t), mask))
        a_h = GRAVITY_M_S2 * np.tan(np.radians(mean_acceleration_tilt_deg(f, 0.5)))
        accel.append(float(np.nanmedian(a_h[mask])))
        for name, run in runs.items():
            if name == OURS:
                q = ours.quaternion
            elif name == "vqf" and vqf is not None:
                q = vqf["6d"]
            else:
                q = run(f)
            measured[name].append(score(f, q))
            for part, window in zip(split[name], ((SETTLE_S, SPLIT_S), (SPLIT_S, math.inf)),
                                    strict=True):
                part.append(score(f, q, window))
    return FamilyFloors(family, len(flights), float(np.median(accel)),
                        {t: float(np.mean(v)) for t, v in floors.items()},
                        {k: float(np.mean(v)) for k, v in measured.items()},
                        {k: (float(np.nanmean(a)), float(np.nanmean(b)) if np.isfinite(b).any()
                             else math.nan) for k, (a, b) in split.items()},
                        float(np.mean(bias_ref)), float(np.mean(bias_err)),
                        float(np.mean(bias_err_end)),
                        (float(np.mean([e[0] for e in vqf_err])),
                         float(np.mean([e[1] for e in vqf_err]))) if vqf_err
                        else (math.nan, math.nan),
                        RotorDrag(*(float(np.median([getattr(d, k.name) for d in drags]))
                                    for k in dataclasses.fields(RotorDrag))))


def score(flight: Flight, q: np.ndarray, window: tuple[float, float] = (SETTLE_S, math.inf)
          ) -> float:
    """Inclination RMS [deg] of ``q`` over the samples with a reference in ``window``
    [s, s) (default: t ≥ SETTLE_S, the scored samples); NaN if there are none."""
    mask = (flight.t_s >= window[0]) & (flight.t_s < window[1]) & flight.has_reference
    return _rms(metrics.inclination_error_deg(q, flight.q_ref), mask)


def drift_deg(memory_s: float, bias_deg_s: float = BIAS_RESIDUAL_DEG_S) -> float:
    """The gyro drift over a memory T [s] with a bias residual δb [deg/s]: δb·T/2 [deg]."""
    return bias_deg_s * memory_s / 2.0


def format_table(rows: Sequence[FamilyFloors]) -> str:
    """The floors and the measured errors, one column per family."""
    names = [r.family for r in rows]
    width = max(12, *(len(n) for n in names))
    head = f"  {'':58s}" + "".join(f"{n:>{width + 2}s}" for n in names)
    lines = [head, f"  {'recordings':58s}" + "".join(f"{r.n:>{width + 2}d}" for r in rows),
             f"  {'median horizontal acceleration [m/s^2]':58s}"
             + "".join(f"{r.median_horizontal_accel_m_s2:>{width + 2}.2f}" for r in rows)]
    for t in MEMORIES_S:
        label = (f"IMU-only floor, memory {t:g} s [deg] (drift "
                 f"{drift_deg(t):.2f} at {BIAS_RESIDUAL_DEG_S:g} deg/s)")
        lines.append(f"  {label:58s}" + "".join(f"{r.floor_deg[t]:>{width + 2}.2f}" for r in rows))
    for t in MEMORIES_S:
        label = f"IMU-only floor with the drift, memory {t:g} s [deg]"
        lines.append(f"  {label:58s}" + "".join(
            f"{math.hypot(r.floor_deg[t], drift_deg(t)):>{width + 2}.2f}" for r in rows))
    for name in rows[0].measured_deg:
        label = f"measured: {name} [deg]"
        lines.append(f"  {label:58s}"
                     + "".join(f"{r.measured_deg.get(name, math.nan):>{width + 2}.2f}"
                               for r in rows))
    for name in rows[0].measured_split_deg:
        for j, part in enumerate((f"{SETTLE_S:g}-{SPLIT_S:g} s", f"after {SPLIT_S:g} s")):
            label = f"measured: {name}, {part} [deg]"
            lines.append(f"  {label:58s}" + "".join(
                f"{r.measured_split_deg.get(name, (math.nan, math.nan))[j]:>{width + 2}.2f}"
                for r in rows))
    lines.append(f"  {'gyro bias the reference shows |b_ref| [deg/s]':58s}"
                 + "".join(f"{r.reference_bias_deg_s:>{width + 2}.2f}" for r in rows))
    label = f"ours online: learned-bias error at {SETTLE_S:g} s [deg/s]"
    lines.append(f"  {label:58s}" + "".join(f"{r.bias_error_deg_s:>{width + 2}.2f}" for r in rows))
    label = "ours online: learned-bias error at the end [deg/s]"
    lines.append(f"  {label:58s}"
                 + "".join(f"{r.bias_error_end_deg_s:>{width + 2}.2f}" for r in rows))
    drag_rows = (
        (f"rotor drag: across the thrust, f = -K*v: K [1/s] (sim {DRAG_PER_S:g})", "k_per_s"),
        ("rotor drag: share of that force explained (R^2)", "explained"),
        ("rotor drag: error of the velocity it implies [m/s]", "velocity_error_m_s"),
        ("velocity across the thrust axis: its swing [m/s]", "velocity_swing_m_s"),
    )
    if all(r.rotor_drag is not None for r in rows):
        for label, name in drag_rows:
            lines.append(f"  {label:58s}" + "".join(
                f"{getattr(r.rotor_drag, name):>{width + 2}.2f}" for r in rows))
    if any(math.isfinite(r.vqf_bias_error_deg_s[0]) for r in rows):
        for j, when in enumerate((f"{SETTLE_S:g} s", "the end")):
            label = f"vqf online: learned-bias error at {when} [deg/s]"
            lines.append(f"  {label:58s}" + "".join(
                f"{r.vqf_bias_error_deg_s[j]:>{width + 2}.2f}" for r in rows))
    return "\n".join(lines) + "\n"


def plot(rows: Sequence[FamilyFloors], example: Flight, series: Mapping[str, np.ndarray],
         out_png: str) -> None:
    """Left: one recording's accelerometer disagreement, 5 s floor and estimators' inclination
    errors over time; right: the floor e_acc(T), the drift δb·T/2 and the measured errors."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 4.6))
    t = example.t_s
    a.plot(t, mean_acceleration_tilt_deg(example, 0.5), color="0.6", lw=0.8,
           label="accelerometer off the vertical (0.5 s)")
    a.plot(t, mean_acceleration_tilt_deg(example, 5.0), color="k", ls="--", lw=1.0,
           label="IMU-only floor, 5 s memory")
    for name, q in series.items():
        e = metrics.inclination_error_deg(q, example.q_ref)
        m = np.isfinite(e)
        a.plot(t[m], e[m], lw=1.0, label=name)
    a.axvline(SETTLE_S, color="0.8", lw=0.8)
    a.set_xlabel("time [s]")
    a.set_ylabel("inclination [deg]")
    a.set_title(f"{example.name}")
    a.legend(fontsize=7)
    a.grid(alpha=0.3)
    memories = np.array(MEMORIES_S)
    for i, r in enumerate(rows):
        b.plot(memories, [r.floor_deg[x] for x in MEMORIES_S], "o-", color=f"C{i}",
               label=f"{r.family}: mean acceleration over T")
        b.plot(memories, [math.hypot(r.floor_deg[x], drift_deg(x)) for x in MEMORIES_S], ":",
               color=f"C{i}", label=f"{r.family}: with the drift")
    b.plot(memories, [drift_deg(x) for x in MEMORIES_S], "k--",
           label=f"gyro drift, {BIAS_RESIDUAL_DEG_S:g} deg/s bias residual")
    for j, (name, value) in enumerate(rows[0].measured_deg.items()):  # the first family's
        b.axhline(value, color=f"C{j + len(rows)}", lw=1.2, label=f"{rows[0].family}: {name}")
    b.set_xscale("log")
    b.set_xlabel("filter memory T [s]")
    b.set_ylabel("inclination RMS after 10 s [deg]")
    b.set_title("what an IMU-only filter cannot avoid")
    b.legend(fontsize=6, ncol=2)
    b.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(out_png, dpi=90)
    plt.close(fig)
