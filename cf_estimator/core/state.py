"""The filter's state, typed and grouped by the part of the filter that owns each field.

Four parts, each a module of its own, update their own fields (and read the others'):

- **compensation loop** (:mod:`cf_estimator.core.step`): attitude, aperiodic unit,
  linear-acceleration detector, phases;
- **rest/motion classifier** (:mod:`cf_estimator.core.stillness`): block statistics, rest,
  the learned gravity norm;
- **bias estimator** (:mod:`cf_estimator.core.bias`): the gyro-bias estimate and its variance;
- **heading channel** (``heading`` in :mod:`cf_estimator.core.step`): field reference,
  yaw-rate correction, heading recovery;

plus the **signals** of the last step (what diagnostics and ``estimate()`` report).

Every field is a float/bool (one filter) or an array of shape (P,) (P parameter sets, the
batched filter): the step is written once for both (:mod:`cf_estimator.core.ops`). The compiled
twin holds the same fields in a C struct (``c/cf_core.h``; ``_kernel.c`` lists them in the same
order, tested). Frames: q_world(ENU)_from_sensor; "sensor" = the IMU's axes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Field:
    """One state field: ``kind`` 'float' | 'bool' | 'int', ``unit`` and meaning."""

    name: str
    kind: str
    unit: str
    doc: str


def _f(name: str, unit: str, doc: str, kind: str = "float") -> Field:
    return Field(name, kind, unit, doc)


def _vec(prefix: str, unit: str, doc: str, axes: str = "xyz") -> tuple[Field, ...]:
    return tuple(_f(f"{prefix}{a}", unit, f"{doc} ({a})") for a in axes)


#: R̄: R (sensor -> world) low-passed as the aperiodic unit (step.learning_input), row-major.
LAGGED_ROTATION: tuple[Field, ...] = (
    *_vec("rx", "1", "R (sensor -> world) low-passed as the aperiodic unit, its row x (world "
          "x in the sensor frame's components; all 0: not set yet)"),
    *_vec("ry", "1", "R low-passed as the aperiodic unit, its row y"),
    *_vec("rz", "1", "R low-passed as the aperiodic unit, its row z"),
)

LOOP: tuple[Field, ...] = (
    _f("qw", "1", "attitude q_world(ENU)_from_sensor, w"),
    *_vec("q", "1", "attitude q_world(ENU)_from_sensor"),
    *_vec("l", "rad", "aperiodic unit's state, world frame"),
    *LAGGED_ROTATION,
    _f("time_s", "s", "time since initialisation"),
    _f("clip_timer_s", "s", "how long the error has been clipped without a break"),
    _f("recovering", "", "tilt recovery in progress", "bool"),
    _f("recovery_count", "1", "recoveries so far"),
    _f("accel_hold", "m/s^2", "peak hold of | |a| - g_ref | (linear-acceleration detector)"),
    *_vec("ac", "m/s^2", "accelerometer low-passed over 50 ms (detector), sensor frame"),
    _f("rate_lp", "rad/s", "low-passed bias-corrected rotation rate"),
    _f("phase", "1", "0 uninitialized, 1 startup, 2 running, 3 recovering", "int"),
    _f("aided", "", "the accelerometer sample of this step is velocity-aided (set by the "
       "caller)", "bool"),
    _f("quick_until_s", "s", "the loop runs as in start-up until this time (a take-hold "
       "phase: velocity aiding that just began); 0: none"),
)

CLASSIFIER: tuple[Field, ...] = (
    _f("rest_timer_s", "s", "duration of the current run of still blocks"),
    _f("at_rest", "", "still for two blocks: the bias is measured from the gyro", "bool"),
    _f("moved", "", "a non-still block was seen since initialisation", "bool"),
    _f("blk_n", "1", "samples in the current block"),
    _f("blk_t", "s", "duration of the current block"),
    *_vec("blk_g", "rad/s", "sum of the block's gyro samples"),
    *_vec("blk_a", "m/s^2", "sum of the block's accelerometer samples"),
    _f("blk_g2", "(rad/s)^2", "sum of squared sample-to-sample gyro differences"),
    _f("blk_a2", "(m/s^2)^2", "sum of squared sample-to-sample accelerometer differences"),
    _f("blk_d", "1", "differences summed in the block"),
    *_vec("blk_m", "1", "sum of the block's unit magnetometer vectors"),
    _f("blk_mn", "1", "magnetometer samples in the block"),
    _f("blk_m2", "1", "sum of squared sample-to-sample differences of the unit field direction"),
    _f("blk_md", "1", "field-direction differences summed in the block"),
    _f("prev_n", "1", "samples in the previous block (0: none yet)"),
    *_vec("pg", "rad/s", "previous block's gyro mean"),
    *_vec("pa", "m/s^2", "previous block's accelerometer mean"),
    *_vec("pm", "1", "previous block's mean field direction (unit)"),
    _f("pm_n", "1", "magnetometer samples in the previous block"),
    _f("last_n", "1", "samples seen (for the differences)"),
    *_vec("lg", "rad/s", "last gyro sample"),
    *_vec("la", "m/s^2", "last accelerometer sample"),
    *_vec("lm", "1", "last unit field direction (all 0: none yet)"),
    _f("noise_g2", "(rad/s)^2", "last block's gyro noise variance (sum over axes)"),
    _f("noise_a2", "(m/s^2)^2", "last block's accelerometer noise variance (sum over axes)"),
    _f("noise_m2", "1", "field-direction noise variance (sum over axes) of the last block with "
       "magnetometer samples"),
    _f("g_ref", "m/s^2", "gravity norm: the prior, then |a| of still blocks"),
)

BIAS: tuple[Field, ...] = (
    *_vec("b", "rad/s", "gyro-bias estimate (the regulator's integral), sensor frame"),
    _f("bias_var", "(rad/s)^2", "variance of the bias estimate per axis (< 0: not set yet): "
       "the learning's schedule"),
    _f("bias_err_var", "(rad/s)^2", "variance of the bias estimate's error per axis (< 0: not "
       "set yet): as bias_var, but shrinking twice as fast while the integral learns"),
    _f("bias_unverified", "", "last rest measurement came from a power-on still phase without "
       "a magnetometer (a steady turn cannot be told from rest then)", "bool"),
    *_vec("pv", "rad*s", "pseudo-velocity over g: the accelerometer's disagreement integrated in "
          "the world frame, high-passed over SWING_TIME_CONSTANT_S", "xy"),
    _f("pv_var", "rad^2*s^2", "mean square of |pv|: the vehicle's velocity swing over g^2"),
    _f("turn_rate_lp", "rad/s", "bias-corrected rotation rate about the estimated vertical, "
       "low-passed: the vehicle turning"),
    _f("turn_hold", "rad/s", "|turn_rate_lp| held, decaying over the loop's memory 1/k1: the "
       "turn whose lean the loop's error still holds"),
)

HEADING: tuple[Field, ...] = (
    _f("z_m", "rad/s", "heading channel's yaw-rate correction, world z"),
    _f("mag_ref_norm", "any", "field norm reference (the magnetometer's unit)"),
    _f("mag_ref_dip", "rad", "field dip reference"),
    _f("mag_ref_count", "1", "samples in the reference"),
    _f("mag_disturbed", "", "last sample rejected: off the reference, or not yet settled "
       "back (latched)", "bool"),
    _f("mag_last_time_s", "s", "time of the last used sample (< 0: none)"),
    _f("heading_initialized", "", "a heading has been taken from the magnetometer", "bool"),
    _f("mag_clip_timer_s", "s", "how long the heading error has been saturated"),
    _f("mag_recovering", "", "heading recovery in progress", "bool"),
    *_vec("mv", "1", "field direction the gyro predicts: used samples, low-passed and turned by "
          "the gyro, sensor frame"),
    *_vec("mc", "1", "candidate field direction: the rejected field's when the candidate began, "
          "turned by the gyro, sensor frame"),
    *_vec("mm", "1", "measured field direction: every sample, low-passed and turned by the "
          "gyro, sensor frame"),
    _f("mag_cand_norm", "any", "candidate field norm: the rejected field's when it began"),
    _f("mag_seen_time_s", "s", "time of the last magnetometer sample, used or not (< 0: none)"),
    _f("mag_ok_timer_s", "s", "how long the field has agreed with the reference without a break"),
    _f("mag_cand_timer_s", "s", "how long a rejected field has been steady and as the gyro "
       "predicts (re-learning)"),
    _f("mag_on_body", "", "the rejected field moved with the body as it turned (a magnet on the "
       "sensor): it does not contradict the heading; until a sample is used", "bool"),
    _f("mag_ref_time_s", "s", "time the field reference was (re-)learned"),
)

SIGNALS: tuple[Field, ...] = (
    *_vec("e", "rad", "last raw error (a/g) x predicted up, sensor frame"),
    _f("error_norm", "rad", "|e|"),
    *_vec("f", "rad", "last processed error (after clip and aperiodic unit), sensor frame"),
    _f("clipped", "", "the last error was clipped", "bool"),
    _f("accel_used", "", "the last step had a valid accelerometer sample", "bool"),
    _f("mag_status", "1", "0 none, 1 used, 2 rejected, 3 disabled", "int"),
    _f("yaw_error_rad", "rad", "heading error the last sample implies (0 unless used, or "
       "rejected and not on the body)"),
    _f("loop_k1", "1/s", "the loop's running gain at the last step with an accelerometer sample, "
       "without the bias-learning raise: the configured k1, lowered by the velocity swing "
       "(bias.loop_gain), at least 2 sqrt(k2)"),
)

GROUPS: dict[str, tuple[Field, ...]] = {
    "loop": LOOP, "classifier": CLASSIFIER, "bias": BIAS, "heading": HEADING,
    "signals": SIGNALS,
}
ALL_FIELDS: tuple[Field, ...] = tuple(f for g in GROUPS.values() for f in g)


class StepState:
    """The filter state: one attribute per :data:`ALL_FIELDS` entry (see the module docstring
    for units, frames and which part owns it)."""

    #: field names in order (the compiled twin lists the same)
    FIELDS: list[str] = [f.name for f in ALL_FIELDS]
    BOOL_FIELDS: tuple[str, ...] = tuple(f.name for f in ALL_FIELDS if f.kind == "bool")

    # typed attributes (float | bool | int for one filter, arrays for a batch): see ALL_FIELDS
    qw: Any
    qx: Any
    qy: Any
    qz: Any
    bx: Any
    by: Any
    bz: Any
    bias_var: Any
    at_rest: Any
    phase: Any

    def __init__(self, zero: Any, false: Any) -> None:
        """``zero``/``false``: 0.0/False for one filter, or zero/False arrays of shape (P,)."""
        for name in self.FIELDS:
            setattr(self, name, zero * 1.0)
        for name in self.BOOL_FIELDS:
            setattr(self, name, false & True)
        self.qw = zero + 1.0
        self.mag_last_time_s = zero - 1.0
        self.mag_seen_time_s = zero - 1.0
        self.bias_var = zero - 1.0  # < 0: not yet set from the parameters (first step sets it)
        self.bias_err_var = zero - 1.0

    def copy(self) -> StepState:
        """A copy (arrays copied too)."""
        new = StepState.__new__(StepState)
        for name in self.FIELDS:
            value = getattr(self, name)
            setattr(new, name, value.copy() if hasattr(value, "copy") else value)
        return new
