"""Named scenarios: truth + simulated IMU + the sensor model + where the disturbances are.

Every scenario is reproducible from ``seed`` (one ``numpy.random.default_rng(seed)`` drives the
motion, the disturbance draws and the sensor noise, in that order). Frames and units as in
:mod:`cf_estimator.scenarios.motion` and :mod:`cf_estimator.scenarios.sensors`.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from cf_estimator.core.quaternion import from_euler as quat_from_euler_zyx
from cf_estimator.scenarios import disturbances as dist
from cf_estimator.scenarios.motion import (
    Truth,
    hover,
    multirotor_circles,
    multirotor_flight,
    multirotor_zigzag,
    static,
    uav_flight,
)
from cf_estimator.scenarios.sensors import ImuData, SensorModel, measure

Window = tuple[float, float, str]


@dataclass(frozen=True, eq=False)
class Scenario:
    """A simulated run with known truth.

    Attributes:
        name: scenario name (a key of :data:`SCENARIOS`).
        truth: the true motion (orientation ``q_world_from_body``, ENU).
        imu: the simulated sensor readings (sensor = body frame), disturbances included.
        model: the sensor error model used.
        description: one paragraph: motion, disturbances, sensor model.
        disturbance_windows: (start_s, end_s, label) of each disturbance, in time order;
            labels ``"impacts"``, ``"vibration"``, ``"acceleration"``.
        rate_hz: sample rate [Hz].
        seed: the seed it was generated from.
        events: named times [s] of the run (``uav``: rotors_on, takeoff, cruise, landing,
            touchdown, rotors_off); empty for the others.
    """

    name: str
    truth: Truth
    imu: ImuData
    model: SensorModel
    description: str
    disturbance_windows: list[Window]
    rate_hz: float
    seed: int
    events: dict[str, float] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        """Length of the run [s] (N samples span N/rate)."""
        return float(self.truth.n_samples / self.rate_hz)

    @property
    def gyro_bias_true_rad_s(self) -> np.ndarray:
        """The true gyro bias (N, 3) [rad/s] in the sensor frame (constant + random walk; rotor
        vibration and white noise are not bias)."""
        assert self.imu.gyro_bias_rad_s is not None
        return self.imu.gyro_bias_rad_s


ScenarioFactory = Callable[..., Scenario]
"""``factory(rate_hz | None, duration_s | None, seed, **options) -> Scenario``."""

DEFAULT_RATE_HZ = {
    "static": 200.0, "static_150": 200.0, "flight": 200.0, "impacts": 1000.0,
    "vibration": 1000.0, "acceleration": 200.0, "thesis": 1000.0, "uav": 200.0,
    "zigzag": 120.0, "circles": 1000.0,
}
"""Default sample rate [Hz] of each scenario (impacts and vibration need ≥ 500/480 Hz)."""

DEFAULT_DURATION_S = {
    "static": 60.0, "static_150": 60.0, "flight": 120.0, "impacts": 70.0, "vibration": 55.0,
    "acceleration": 45.0, "thesis": 120.0, "uav": 120.0, "zigzag": 45.0, "circles": 60.0,
}
"""Default duration [s] of each scenario."""

_MIN_DURATION_S = {
    "static": 1.0, "static_150": 1.0, "flight": 20.0, "impacts": 60.0, "vibration": 45.0,
    "acceleration": 20.0, "thesis": 110.0, "uav": 40.0, "zigzag": 15.0, "circles": 15.0,
}

# Thesis disturbance layout [s]
_IMPACTS_START = 10.0
#: Vibration axis in the sensor frame: oblique (45° between forward and up). The thesis does not
#: give an axis; a purely horizontal sine is symmetric about gravity and averages out in any
#: filter, while an oblique one (the usual case on a real mount) rectifies into a tilt bias
#: unless the error is clipped: the case worth testing.
VIBRATION_AXIS = (1.0, 0.0, 1.0)
_VIBRATION_START, _VIBRATION_LEN = 10.0, 30.0
_ACCEL_START, _ACCEL_LEN = 10.0, 5.0
_THESIS_IMPACTS = 15.0
_THESIS_VIBRATION, _THESIS_VIBRATION_LEN = 65.0, 25.0
_THESIS_ACCEL = 100.0


def _setup(name: str, rate_hz: float | None, duration_s: float | None) -> tuple[float, float]:
    rate = DEFAULT_RATE_HZ[name] if rate_hz is None else float(rate_hz)
    duration = DEFAULT_DURATION_S[name] if duration_s is None else float(duration_s)
    if not rate > 0:
        raise ValueError(f"rate_hz must be > 0, got {rate}")
    if duration < _MIN_DURATION_S[name]:
        raise ValueError(
            f"scenario {name!r} needs duration_s >= {_MIN_DURATION_S[name]:g} s, got {duration:g}"
        )
    return rate, duration


def _impacts_window(start: float) -> Window:
    end = float(dist.impact_times(start)[-1]) + 0.015
    return (start, end, "impacts")


_IMPACTS_TEXT = "60 rectangular +x impacts of 15 g, 10-15 ms each (uniform draw), 80 per minute"
_VIBRATION_TEXT = "sinusoidal +x vibration of 6 g, linear sweep 20->120 Hz"
_ACCEL_TEXT = "forward acceleration of 5 m/s^2 for 5 s (25 m/s gained, kept afterwards)"


def _finish(
    name: str, truth: Truth, model: SensorModel, rng: np.random.Generator, rate: float, seed: int,
    description: str, windows: list[Window], disturbance: np.ndarray | None = None,
) -> Scenario:
    imu = measure(truth, model, rng)
    if disturbance is not None:
        imu = imu.with_accel_disturbance(disturbance)
    return Scenario(name, truth, imu, model, description, sorted(windows), rate, seed)


def scenario_static(rate_hz: float | None, duration_s: float | None, seed: int) -> Scenario:
    """Level IMU at rest (yaw 30°), default MEMS sensor model."""
    rate, duration = _setup("static", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    truth = static(duration, rate, quat_from_euler_zyx(0.0, 0.0, np.deg2rad(30.0)))
    text = "IMU at rest on a level base (roll 0, pitch 0, yaw 30 deg); default MEMS model."
    return _finish("static", truth, SensorModel(), rng, rate, seed, text, [])


def scenario_static_150(rate_hz: float | None, duration_s: float | None, seed: int) -> Scenario:
    """IMU at rest at roll 150° (thesis: angles ±150° on a fixed base), default MEMS model."""
    rate, duration = _setup("static_150", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    truth = static(duration, rate, quat_from_euler_zyx(np.deg2rad(150.0), 0.0, np.deg2rad(30.0)))
    text = "IMU at rest at roll 150 deg, pitch 0, yaw 30 deg (nearly upside down); default MEMS."
    return _finish("static_150", truth, SensorModel(), rng, rate, seed, text, [])


def scenario_flight(rate_hz: float | None, duration_s: float | None, seed: int) -> Scenario:
    """Multirotor flight (take-off, tilts of 10–30°, turns, speed changes, landing)."""
    rate, duration = _setup("flight", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    truth = uav_flight(duration, rate, rng)
    text = (
        "UAV flight: 2 s on the ground, take-off, random roll/pitch manoeuvres of 10-30 deg, "
        "banked yaw turns of 30-150 deg, forward speed changes up to 6 m/s (|a| <= 4 m/s^2), "
        "stop, landing; default MEMS sensor model (gyro bias std 0.1 deg/s)."
    )
    return _finish("flight", truth, SensorModel(), rng, rate, seed, text, [])


def scenario_impacts(rate_hz: float | None, duration_s: float | None, seed: int) -> Scenario:
    """Hover with a small wobble plus the thesis's 60 impacts from t = 10 s."""
    rate, duration = _setup("impacts", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    truth = hover(duration, rate, rng)
    d = dist.impacts(truth.t_s, _IMPACTS_START, rng=rng)
    text = (
        f"Hover with a small attitude wobble (<= 3 deg tilt); {_IMPACTS_TEXT}, from "
        f"{_IMPACTS_START:g} s; accelerometer only; thesis sensor model (gyro bias 10 deg/h)."
    )
    windows = [_impacts_window(_IMPACTS_START)]
    return _finish("impacts", truth, SensorModel.thesis(), rng, rate, seed, text, windows, d)


def scenario_vibration(rate_hz: float | None, duration_s: float | None, seed: int) -> Scenario:
    """Hover with a small wobble plus 30 s of 6 g, 20→120 Hz sweep vibration from t = 10 s."""
    rate, duration = _setup("vibration", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    truth = hover(duration, rate, rng)
    d = dist.vibration(truth.t_s, _VIBRATION_START, _VIBRATION_LEN, direction_body=VIBRATION_AXIS)
    text = (
        f"Hover with a small attitude wobble (<= 3 deg tilt); {_VIBRATION_TEXT} over "
        f"{_VIBRATION_START:g}-{_VIBRATION_START + _VIBRATION_LEN:g} s; accelerometer only; "
        "thesis sensor model (gyro bias 10 deg/h)."
    )
    windows = [(_VIBRATION_START, _VIBRATION_START + _VIBRATION_LEN, "vibration")]
    return _finish("vibration", truth, SensorModel.thesis(), rng, rate, seed, text, windows, d)


def scenario_acceleration(rate_hz: float | None, duration_s: float | None, seed: int) -> Scenario:
    """Hover with a small wobble, then 25 m/s gained in 5 s (a real motion) from t = 10 s."""
    rate, duration = _setup("acceleration", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    truth = dist.acceleration_manoeuvre(hover(duration, rate, rng), _ACCEL_START)
    text = (
        f"Hover with a small attitude wobble (<= 3 deg tilt); {_ACCEL_TEXT} along the heading, "
        f"{_ACCEL_START:g}-{_ACCEL_START + _ACCEL_LEN:g} s, attitude unchanged (real motion, in "
        "the truth); thesis sensor model (gyro bias 10 deg/h)."
    )
    windows = [(_ACCEL_START, _ACCEL_START + _ACCEL_LEN, "acceleration")]
    return _finish("acceleration", truth, SensorModel.thesis(), rng, rate, seed, text, windows)


def scenario_thesis(rate_hz: float | None, duration_s: float | None, seed: int) -> Scenario:
    """Flight with the three thesis disturbances in sequence, quiet stretches between."""
    rate, duration = _setup("thesis", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    imp = _impacts_window(_THESIS_IMPACTS)
    vib = (_THESIS_VIBRATION, _THESIS_VIBRATION + _THESIS_VIBRATION_LEN, "vibration")
    acc = (_THESIS_ACCEL, _THESIS_ACCEL + _ACCEL_LEN, "acceleration")
    calm = [(imp[0], imp[1]), (vib[0], vib[1]), (acc[0], duration)]
    truth = uav_flight(
        duration, rate, rng, min_tilt_deg=5.0, max_tilt_deg=15.0, max_speed_m_s=0.0,
        land=False, calm_windows=calm,
    )
    truth = dist.acceleration_manoeuvre(truth, _THESIS_ACCEL)
    d = dist.impacts(truth.t_s, _THESIS_IMPACTS, rng=rng)
    d += dist.vibration(truth.t_s, vib[0], _THESIS_VIBRATION_LEN, direction_body=VIBRATION_AXIS)
    text = (
        "Thesis flight: 2 s on the ground, take-off, gentle manoeuvres (tilts 5-15 deg, yaw "
        "turns, no translation) only in the quiet stretches, steady hover during each window: "
        f"{_IMPACTS_TEXT} ({imp[0]:g}-{imp[1]:.2f} s); "
        f"{_VIBRATION_TEXT} ({vib[0]:g}-{vib[1]:g} s); "
        f"{_ACCEL_TEXT} ({acc[0]:g}-{acc[1]:g} s). Thesis sensor model (gyro bias 10 deg/h)."
    )
    return _finish("thesis", truth, SensorModel.thesis(), rng, rate, seed, text,
                   [imp, vib, acc], d)


#: Default constant gyro bias of the ``uav`` scenario [rad/s] (sensor x, y, z): uncalibrated
#: MEMS-gyro size (EuRoC's ADIS16448: ≈ (−0.002, 0.021, 0.077)), large on every axis.
UAV_GYRO_BIAS_RAD_S = (0.06, -0.08, 0.1)


def scenario_uav(
    rate_hz: float | None, duration_s: float | None, seed: int, *,
    gyro_bias_rad_s: tuple[float, float, float] = UAV_GYRO_BIAS_RAD_S,
    vibration_m_s2: float = 3.0, gyro_vibration_rad_s: float = 0.03,
    cruise_speed_m_s: float = 6.0, land: bool = True, model: SensorModel | None = None,
) -> Scenario:
    """Multirotor: large gyro bias, rotor vibration on the ground and in flight, cruise, turns."""
    rate, duration = _setup("uav", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    flight = multirotor_flight(duration, rate, rng, cruise_speed_m_s=cruise_speed_m_s, land=land)
    acc_vib, gyro_vib = dist.rotor_vibration(flight.truth.t_s, flight.rotor_speed, rng,
                                             accel_rms_m_s2=vibration_m_s2,
                                             gyro_rms_rad_s=gyro_vibration_rad_s)
    base = SensorModel() if model is None else model
    sensor = dataclasses.replace(base, gyro_bias_rad_s=tuple(float(b) for b in gyro_bias_rad_s))
    ev = flight.events
    bias = ", ".join(f"{b:g}" for b in sensor.gyro_bias_rad_s or ())
    text = (
        f"Multirotor flight: at rest on the ground, rotors on at {ev['rotors_on']:g} s (idle "
        f"vibration), take-off at {ev['takeoff']:g} s, cruise at {cruise_speed_m_s:g} m/s from "
        f"{ev['cruise']:g} s with coordinated turns, climbs and speed changes; attitude set by "
        "thrust (tilt = acceleration and linear drag), accelerometer along body z plus rotor "
        "drag; " + (f"landing {ev['landing']:.1f}-{ev['touchdown']:.1f} s; " if land else "")
        + f"constant gyro bias ({bias}) rad/s; rotor vibration {vibration_m_s2:g} m/s^2 and "
        f"{gyro_vibration_rad_s:g} rad/s RMS at hover (6 rotors, 1x and 2x rotor speed, "
        "50-180 Hz, aliased as sampled); default MEMS noise."
    )
    windows = [(ev["rotors_on"], ev.get("rotors_off", flight.truth.t_s[-1]), "vibration")]
    imu = measure(flight.truth, sensor, rng)
    imu = imu.with_accel_disturbance(acc_vib).with_gyro_disturbance(gyro_vib)
    return Scenario("uav", flight.truth, imu, sensor, text, windows, rate, seed, dict(ev))


#: Default constant gyro bias of the ``zigzag`` scenario [rad/s]: the Xsens DOTs' size on the
#: Phantom 4 (|b| = 1.67 °/s; the reference shows 1.60 °/s on average, `cf-estimator bench
#: sustained`'s |b_ref| row), which an in-air start must learn in flight.
ZIGZAG_GYRO_BIAS_RAD_S = (0.02, -0.015, 0.015)


def scenario_zigzag(
    rate_hz: float | None, duration_s: float | None, seed: int, *,
    gyro_bias_rad_s: tuple[float, float, float] = ZIGZAG_GYRO_BIAS_RAD_S,
    accel_m_s2: float = 4.0, leg_speed_m_s: float = 6.0, vibration_m_s2: float = 3.0,
    gyro_vibration_rad_s: float = 0.03, model: SensorModel | None = None,
) -> Scenario:
    """Horizontal zig-zags (:func:`~cf_estimator.scenarios.motion.multirotor_zigzag`), in the
    air from the first sample, 120 Hz like the Phantom's DOTs, rotor vibration."""
    rate, duration = _setup("zigzag", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    flight = multirotor_zigzag(duration, rate, rng, leg_speed_m_s=leg_speed_m_s,
                               accel_m_s2=accel_m_s2)
    acc_vib, gyro_vib = dist.rotor_vibration(flight.truth.t_s, flight.rotor_speed, rng,
                                             accel_rms_m_s2=vibration_m_s2,
                                             gyro_rms_rad_s=gyro_vibration_rad_s)
    base = SensorModel() if model is None else model
    sensor = dataclasses.replace(base, gyro_bias_rad_s=tuple(float(b) for b in gyro_bias_rad_s))
    bias = ", ".join(f"{b:g}" for b in sensor.gyro_bias_rad_s or ())
    text = (f"Multirotor horizontal zig-zags, in the air from the first sample: back and forth "
            f"between ±{leg_speed_m_s:g} m/s along the heading at {accel_m_s2:g} m/s^2 mean "
            "acceleration, legs held 0-0.5 s, hovers and heading changes now and then; thrust "
            f"along body z plus rotor drag; constant gyro bias ({bias}) rad/s; rotor vibration "
            f"{vibration_m_s2:g} m/s^2 and {gyro_vibration_rad_s:g} rad/s RMS; default MEMS "
            "noise.")
    imu = measure(flight.truth, sensor, rng)
    imu = imu.with_accel_disturbance(acc_vib).with_gyro_disturbance(gyro_vib)
    windows = [(float(flight.truth.t_s[0]), float(flight.truth.t_s[-1]), "acceleration")]
    return Scenario("zigzag", flight.truth, imu, sensor, text, windows, rate, seed,
                    dict(flight.events))


def scenario_circles(
    rate_hz: float | None, duration_s: float | None, seed: int, *,
    gyro_bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0), speed_m_s: float = 3.0,
    turn_rate_rad_s: float = 0.6, figure_eight: bool = True, vibration_m_s2: float = 1.0,
    gyro_vibration_rad_s: float = 0.01, model: SensorModel | None = None,
) -> Scenario:
    """Sustained coordinated turns (:func:`~cf_estimator.scenarios.motion.multirotor_circles`),
    in the air from the first sample, figure-8s by default, 1 kHz like a small quadrotor's
    flight controller, whose firmware has already removed the gyro bias (zero by default):
    whatever bias the filter learns is the turn's."""
    rate, duration = _setup("circles", rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    flight = multirotor_circles(duration, rate, rng, speed_m_s=speed_m_s,
                                turn_rate_rad_s=turn_rate_rad_s, figure_eight=figure_eight)
    acc_vib, gyro_vib = dist.rotor_vibration(flight.truth.t_s, flight.rotor_speed, rng,
                                             accel_rms_m_s2=vibration_m_s2,
                                             gyro_rms_rad_s=gyro_vibration_rad_s)
    base = SensorModel() if model is None else model
    sensor = dataclasses.replace(base, gyro_bias_rad_s=tuple(float(b) for b in gyro_bias_rad_s))
    shape = "figure-8s (the turn reversed every loop)" if figure_eight else "circles"
    text = (f"Multirotor {shape} in the air from the first sample at {speed_m_s:g} m/s and "
            f"{turn_rate_rad_s:g} rad/s (centripetal {speed_m_s * turn_rate_rad_s:g} m/s^2, "
            "fixed on the body for each loop); thrust along body z plus rotor drag; gyro bias "
            f"{', '.join(f'{b:g}' for b in sensor.gyro_bias_rad_s or ())} rad/s (removed by "
            f"the firmware); rotor vibration {vibration_m_s2:g} m/s^2 and "
            f"{gyro_vibration_rad_s:g} rad/s RMS; default MEMS noise.")
    imu = measure(flight.truth, sensor, rng)
    imu = imu.with_accel_disturbance(acc_vib).with_gyro_disturbance(gyro_vib)
    windows = [(float(flight.truth.t_s[0]), float(flight.truth.t_s[-1]), "acceleration")]
    return Scenario("circles", flight.truth, imu, sensor, text, windows, rate, seed,
                    dict(flight.events))


SCENARIOS: dict[str, ScenarioFactory] = {
    "static": scenario_static,
    "static_150": scenario_static_150,
    "flight": scenario_flight,
    "impacts": scenario_impacts,
    "vibration": scenario_vibration,
    "acceleration": scenario_acceleration,
    "thesis": scenario_thesis,
    "uav": scenario_uav,
    "zigzag": scenario_zigzag,
    "circles": scenario_circles,
}
"""Scenario factories ``(rate_hz | None, duration_s | None, seed) -> Scenario`` by name."""


def make_scenario(
    name: str, rate_hz: float | None = None, duration_s: float | None = None, seed: int = 0,
    **options: object,
) -> Scenario:
    """Build the named scenario (``rate_hz``/``duration_s`` None = the scenario's default).

    ``options`` go to the scenario's factory (keyword arguments of ``scenario_<name>``, e.g.
    ``make_scenario("uav", gyro_bias_rad_s=(0.1, 0, 0))``). Raises ``ValueError`` naming the
    valid scenarios for an unknown name, for an option the scenario does not take, and for a
    duration below the scenario's minimum or a rate too low for its disturbances.
    """
    try:
        factory = SCENARIOS[name]
    except KeyError:
        raise ValueError(
            f"unknown scenario {name!r}; valid: {', '.join(SCENARIOS)}"
        ) from None
    if options:
        accepted = inspect.signature(factory).parameters
        bad = [k for k in options if k not in accepted or k in ("rate_hz", "duration_s", "seed")]
        if bad:
            raise ValueError(f"scenario {name!r} takes no option {bad[0]!r}")
    return factory(rate_hz, duration_s, seed, **options)
