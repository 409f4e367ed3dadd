"""The processing pipeline: message-like objects in, validated filter calls, output contents out.

The node (live) and the bag replay (offline) both call :class:`ImuPipeline`, so the replay tests
test the node's behaviour. Rules, in the order :meth:`ImuPipeline.on_imu` applies them:

1. Every IMU message is counted as received and ends either *processed* (an output is returned)
   or *rejected* with a counted reason (None is returned): ``received = processed + rejected``.
2. Malformed fields, a zero stamp, NaN/Inf gyro or accelerometer, a zero accelerometer vector,
   a gyro or accelerometer norm beyond any sensor's range (``checks.GYRO_MAX_RAD_S``,
   ``checks.ACCEL_MAX_M_S2``): rejected. Nothing invalid ever reaches the filter.
3. ``dt`` comes from header stamps (integer nanoseconds). ``dt = 0``: rejected
   (``duplicate_stamp``). Slightly negative (< ``time_jump_back_threshold_s``): rejected
   (``out_of_order``). Further back: the filter is reset and the message starts it again
   (``reset_on_time_jump_back``), else rejected (``time_backwards``). Longer than
   ``reset_after_gap_s``: reset and restart. Longer than ``max_dt_s``: the gap is not
   integrated; the message is processed with the recent mean interval and counted in ``gaps``.
4. Magnetometer messages only store the latest valid sample. The next processed IMU message
   passes it to the filter once, if its stamp is within ``mag_timeout_s`` of the IMU stamp
   (else it is counted stale). NaN components are legal ("not reported"): such samples are
   counted invalid and ignored. A magnetometer dropout never stops the output.
5. Unit and frame sanity checks warn once each (see :mod:`cf_estimator.pipeline.checks`).
6. Velocity messages (optional aiding, :meth:`ImuPipeline.on_velocity`; TwistStamped or
   Odometry) go to :class:`cf_estimator.core.velocity.VelocityAiding`, created at the first
   one: until then, and whenever it is not aided, the filter gets the raw accelerometer sample
   exactly as without velocity. Every velocity message is counted used, stale or rejected by
   reason (diagnostics ``velocity_*``); a reset of the filter resets the aiding.

The rules are applied in one place, over arrays (:mod:`cf_estimator.pipeline.process`): the
node passes each message as a chunk of one (:meth:`ImuPipeline.on_imu`, ``on_mag``), a replay
thousands at a time (:meth:`ImuPipeline.process`), with the same outputs and counters, bit for
bit. Statistics are accumulated incrementally and turned into a report only by
:meth:`ImuPipeline.diagnostics`.
"""

from __future__ import annotations

import dataclasses
import math
import traceback
from collections.abc import Mapping
from time import perf_counter
from typing import Any

from cf_estimator.core.filter import ComplementaryFilter
from cf_estimator.core.magcal import MagCorrection
from cf_estimator.core.params import FilterParams
from cf_estimator.core.velocity import VelocityAiding
from cf_estimator.pipeline import checks, frames
from cf_estimator.pipeline.covariance import OrientationCovariance
from cf_estimator.pipeline.diagnostics import (
    DiagnosticsReport,
    WindowStats,
    compose_report,
    velocity_values,
)
from cf_estimator.pipeline.events import Events, imu_message_events, mag_message_events
from cf_estimator.pipeline.params import PipelineParams
from cf_estimator.pipeline.process import PipelineOutput, Rows, process
from cf_estimator.pipeline.state import (
    ImuTime,
    InputCovariance,
    InputRules,
    MagInput,
    MessageCounts,
)
from cf_estimator.pipeline.velocity_input import velocity_from_message
from cf_estimator.schema import ParameterError, as_dict, specs_of, split_by_owner

Vec3 = tuple[float, float, float]
#: An unexpected exception's traceback is reported at most once per this many seconds [s]
#: (wall clock): a bug that hits every message is logged, not flooded.
INTERNAL_ERROR_REPORT_S = 10.0


class ImuPipeline:
    """Validated IMU (+ magnetometer) messages → complementary filter → output contents.

    ``filter_params``/``pipeline_params`` default to the schema defaults. ``diagnostics_name``
    is the ``name`` of the diagnostic status (the node passes its fully qualified name),
    ``imu_topic`` the IMU input topic named in "no IMU messages" reports.
    """

    def __init__(
        self,
        filter_params: FilterParams | None = None,
        pipeline_params: PipelineParams | None = None,
        *,
        diagnostics_name: str = "cf_estimator",
        imu_topic: str = "",
    ) -> None:
        self._fp = filter_params if filter_params is not None else FilterParams()
        self._pp = pipeline_params if pipeline_params is not None else PipelineParams()
        self._filter = ComplementaryFilter(frames.core_params(self._fp))
        self.diagnostics_name = diagnostics_name
        self.imu_topic = imu_topic  #: named in the "no IMU messages" diagnostics (the node's)
        #: cumulative counts (plain ints: the hot path increments attributes)
        self.tally = MessageCounts()
        self._rejected: dict[str, int] = {}
        self._resets: dict[str, int] = {}
        self.reset_total = 0  #: resets of every reason (a cheap "did it reset?" for the node)
        #: the IMU time base (cleared by every reset), the magnetometer input, the rules
        self.clock = ImuTime()
        self.mag_input = MagInput()
        self.rules = InputRules()
        self.last_reject_reason = ""
        # warn-once state
        self._warned: dict[str, str] = {}
        self._pending_warnings: list[str] = []
        #: see :meth:`take_internal_error`
        self.internal_error_traceback: str | None = None
        self._internal_error_at = -math.inf
        self.imu_frame: str | None = None  #: the IMU messages' frame id (None: none yet)
        self.accel_check_n = 0  #: accelerometer samples in the unit check so far
        self.acc_sum = [0.0, 0.0, 0.0]  #: their sum [m/s²]
        #: the diagnostics window (since the last report)
        self.window = WindowStats()
        self._previous_counters: dict[str, Any] = {}
        self._previous_now_s: float | None = None
        self.last_rpy: Vec3 | None = None  #: roll, pitch, yaw [rad] of the last output
        self._aiding: VelocityAiding | None = None  # created by the first velocity message
        #: the input covariances (angular velocity, linear acceleration), cached by their bytes
        self.angular_velocity_covariance = InputCovariance()
        self.linear_acceleration_covariance = InputCovariance()
        #: the orientation covariance model (cf_estimator.core.covariance)
        self.covariance_model = OrientationCovariance(
            self._pp.orientation_covariance_rad2, self._pp.yaw_covariance_rad2,
            self._pp.unreferenced_yaw_covariance_rad2, self._fp.bias_prior_sigma_rad_s,
            self._fp.k1, self._fp.gravity_m_s2, self._fp.r1)
        self._apply_derived()
        self._clear_time_state()

    # -- parameters -------------------------------------------------------------------------------
    @property
    def filter_params(self) -> FilterParams:
        """The filter parameters in force."""
        return self._fp

    @property
    def pipeline_params(self) -> PipelineParams:
        """The pipeline parameters in force."""
        return self._pp

    @property
    def filter(self) -> ComplementaryFilter:
        """The filter (read access for tests and tools; do not drive it directly)."""
        return self._filter

    def _prepare(self, changes: Mapping[str, Any]) -> tuple[FilterParams, PipelineParams]:
        fchanges, pchanges = split_by_owner(changes, (FilterParams, PipelineParams))
        # the schema first (the same one-line reason as at start-up, read-only values included)
        fp = FilterParams(**{**as_dict(self._fp), **fchanges}) if fchanges else self._fp
        pp = PipelineParams(**{**as_dict(self._pp), **pchanges}) if pchanges else self._pp
        pairs = ((FilterParams, self._fp, fp, fchanges), (PipelineParams, self._pp, pp, pchanges))
        for cls, current, new, ch in pairs:
            for spec in specs_of(cls):
                if spec.read_only and spec.name in ch and \
                        getattr(new, spec.name) != getattr(current, spec.name):
                    raise ParameterError(
                        f"{spec.name} is read-only at run time (restart the node to change it)"
                    )
        return fp, pp

    def validate_changes(self, changes: Mapping[str, Any]) -> tuple[bool, str]:
        """Check parameter changes without applying them: ``(ok, reason)``."""
        try:
            self._prepare(changes)
        except Exception as exc:  # noqa: BLE001 - any failure is a rejection with its reason
            return False, str(exc)
        return True, ""

    def apply_changes(self, changes: Mapping[str, Any]) -> tuple[bool, str]:
        """Validate and apply parameter changes: ``(ok, reason)``.

        On success the filter keeps its state (attitude, bias, phase); on failure nothing
        changes. Read-only parameters may only be "changed" to their current value.
        """
        try:
            fp, pp = self._prepare(changes)
        except Exception as exc:  # noqa: BLE001
            return False, str(exc)
        if fp is not self._fp:
            self._filter.set_params(frames.core_params(fp))
            self._fp = fp
            if self._aiding is not None:
                self._aiding.set_params(frames.core_params(fp))
        self._pp = pp
        self._apply_derived()
        return True, ""

    def _apply_derived(self) -> None:
        pp = self._pp
        cov = self.covariance_model
        cov.tilt0 = pp.orientation_covariance_rad2
        cov.yaw0 = pp.yaw_covariance_rad2
        cov.yaw_unref = pp.unreferenced_yaw_covariance_rad2
        cov.bias_prior = self._fp.bias_prior_sigma_rad_s
        cov.k1 = self._fp.k1
        cov.r1 = self._fp.r1
        cov.set_gravity(self._fp.gravity_m_s2)
        self.rules.max_dt_ns = int(round(pp.max_dt_s * 1e9))
        # 0 = never; a positive value below 0.5 ns must not round to "never"
        self.rules.reset_gap_on = pp.reset_after_gap_s > 0.0
        self.rules.reset_gap_ns = int(round(pp.reset_after_gap_s * 1e9))
        self.rules.jump_back_ns = int(round(pp.time_jump_back_threshold_s * 1e9))
        self.rules.mag_timeout_ns = int(round(pp.mag_timeout_s * 1e9))
        self.rules.use_mag = self._fp.use_mag
        #: hard and soft iron, applied to every magnetometer sample before anything else
        self.mag_correction = MagCorrection(pp.mag_hard_iron_t, pp.mag_soft_iron)
        self._ned = self._fp.world_frame == "ned"
        # the published world frame, true north, yaw offset (identity: skipped, bit-identical)
        self._out_frame = frames.OutputFrame(self._fp.world_frame, pp.magnetic_declination_rad,
                                             pp.yaw_offset_rad)
        self._out_frame_ids: dict[str, str] = {}  # input frame_id -> output frame_id
        # velocity (GNSS: true north) into the core's magnetic-north world: the inverse of the
        # declination turn, about ENU's up (+D) or NED's down (-D) axis
        d = pp.magnetic_declination_rad
        d = -d if frames.core_world_frame(self._fp.world_frame) == "ned" else d
        self._vel_turn = (math.cos(d), math.sin(d)) if d else None
        # FLU <-> FRD: (x, y, z) -> (x, -y, -z), a half turn about x. Applied to the input
        # vectors when their convention is not the one paired with the world frame (FLU-ENU,
        # FRD-NED), so the core estimates q_world_from_body in that paired convention.
        bf = pp.body_frame
        self.rules.flip = bf != "sensor" and (bf == "frd") != self._ned
        flip = self.rules.flip
        self.angular_velocity_covariance.flip = self.linear_acceleration_covariance.flip = flip

    # -- state ------------------------------------------------------------------------------------
    def _clear_time_state(self) -> None:
        self.clock = ImuTime()

    def reset(self, reason: str) -> None:
        """Forget the attitude and the time base; the next valid IMU message re-initialises.

        Counted under ``resets[reason]``; a pending magnetometer sample is dropped (it belongs to
        the old time base).
        """
        self._filter.reset()
        if self._aiding is not None:
            self._aiding.reset()
        self.covariance_model.reset()
        self._clear_time_state()
        self._resets[reason] = self._resets.get(reason, 0) + 1
        self.reset_total += 1
        if self.mag_input.pending is not None:
            self.mag_input.pending = None
            self.tally.mag_dropped += 1

    def output_frame_id(self, input_frame_id: str) -> str:
        """The frame id published for an input ``frame_id`` (:func:`frames.output_frame_id`)."""
        out = self._out_frame_ids.get(input_frame_id)
        if out is None:
            out = frames.output_frame_id(input_frame_id, self._pp.output_frame_id,
                                         self._fp.world_frame, self._pp.body_frame)
            self._out_frame_ids[input_frame_id] = out
        return out

    def replace_filter(self, new_filter: ComplementaryFilter) -> None:
        """Run ``new_filter`` (same parameters, e.g. one that records its input for an
        offline pass) instead of the pipeline's own; before the first IMU message only."""
        if self.tally.received_imu:
            raise RuntimeError("replace_filter: messages were already processed")
        self._filter = new_filter

    @property
    def has_velocity_aiding(self) -> bool:
        """True once a velocity message has created the aiding (it then runs per message)."""
        return self._aiding is not None

    @property
    def output_frame(self) -> frames.OutputFrame:
        """The rotation from the core's world frame to the published one."""
        return self._out_frame

    @property
    def converts_axes(self) -> bool:
        """True when ``body_frame`` turns the input vectors half a turn about x (FLU <-> FRD):
        the output's angular velocity, acceleration and their covariances differ from the
        input's."""
        return self.rules.flip

    @property
    def initialized(self) -> bool:
        """True once the filter has an attitude."""
        return self._filter.initialized

    @property
    def counters(self) -> dict[str, Any]:
        """Cumulative counters (a fresh dict; see docs/ros_interface.md)."""
        return {
            "received_imu": self.tally.received_imu,
            "processed": self.tally.processed,
            "rejected": dict(self._rejected),
            "resets": dict(self._resets),
            "gaps": self.tally.gaps,
            "received_mag": self.tally.received_mag,
            "mag_used": self.tally.mag_used,
            "mag_rejected": self.tally.mag_rejected,
            "mag_stale": self.tally.mag_stale,
            "mag_invalid": self.tally.mag_invalid,
            "mag_dropped": self.tally.mag_dropped,
            "mag_disabled": self.tally.mag_disabled,
            "mag_pending": 0 if self.mag_input.pending is None else 1,
        }

    @property
    def rejected_counts(self) -> Mapping[str, int]:
        """IMU rejections by reason (the live dict: read, do not modify)."""
        return self._rejected

    @property
    def reset_counts(self) -> Mapping[str, int]:
        """Resets by reason (the live dict: read, do not modify)."""
        return self._resets

    @property
    def event_counts(self) -> Mapping[str, int]:
        """Events by kind, cumulative: 'attitude_error', a take-hold on an attitude error
        revealed while aided (ComplementaryFilter.apply_aiding; counted by the aiding, which
        keeps its counters across resets)."""
        return {"attitude_error": self.event_total} if self._aiding is not None else {}

    @property
    def event_total(self) -> int:
        """Events of every kind so far (a cheap "did one happen?" for the node)."""
        return self._aiding.attitude_errors if self._aiding is not None else 0

    @property
    def input_warnings(self) -> dict[str, str]:
        """Warn-once messages raised so far, tag → text."""
        return dict(self._warned)

    @property
    def input_warning_tags(self) -> Mapping[str, str]:
        """Warn-once messages raised so far, tag → text (the live dict: read only)."""
        return self._warned

    def take_warnings(self) -> list[str]:
        """The warn-once texts raised since the last call (they go with the next output)."""
        warnings = self._pending_warnings
        if warnings:
            self._pending_warnings = []
            return warnings
        return []

    def covariance_bytes(self) -> bytes | None:
        """The input covariances in force (angular velocity, then linear acceleration) as
        bytes, None before the first IMU message."""
        a, b = self.angular_velocity_covariance.raw, self.linear_acceleration_covariance.raw
        return None if a is None or b is None else a + b

    def warn(self, tag_text: tuple[str, str] | None) -> None:
        """Raise a warn-once ``(tag, text)`` (None: nothing to say): the first time its tag is
        seen it goes with the next output and into the diagnostics."""
        if tag_text is None:
            return
        tag, text = tag_text
        if tag not in self._warned:
            self._warned[tag] = text
            self._pending_warnings.append(text)

    def reject(self, reason: str) -> None:
        """Count one IMU message rejected for ``reason`` (a checks.* code)."""
        self._rejected[reason] = self._rejected.get(reason, 0) + 1
        self.last_reject_reason = reason

    # -- magnetometer -----------------------------------------------------------------------------
    def on_mag(self, msg: Any) -> None:
        """Store the latest valid magnetometer sample (any unit; only directions are used),
        corrected by ``mag_hard_iron_t`` / ``mag_soft_iron`` first (core/magcal.py)."""
        self.process_message(msg, imu=False)

    # -- velocity ---------------------------------------------------------------------------------
    def on_velocity(self, msg: Any) -> str | None:
        """Queue one TwistStamped/Odometry-like velocity message for the aiding (see
        :mod:`cf_estimator.pipeline.velocity_input`); returns None, or the rejection reason
        (counted)."""
        if self._aiding is None:
            self._aiding = VelocityAiding(frames.core_params(self._fp))
        pp = self._pp
        got = velocity_from_message(msg, pp.velocity_frame,
                                    frames.core_world_frame(self._fp.world_frame),
                                    pp.velocity_frame_id)
        if isinstance(got, str):
            self._aiding.reject(got)
            return got
        t_ns, v = got
        if self._vel_turn is not None:  # true-north velocity into the core's magnetic world
            c, s_ = self._vel_turn
            v = (c * v[0] - s_ * v[1], s_ * v[0] + c * v[1], v[2])
        return self._aiding.add_velocity(t_ns * 1e-9, v)

    @property
    def velocity_aiding(self) -> VelocityAiding | None:
        """The velocity aiding (None until the first velocity message)."""
        return self._aiding

    # -- IMU --------------------------------------------------------------------------------------
    def on_imu(self, msg: Any) -> PipelineOutput | None:
        """Process one sensor_msgs/Imu-like message; None when it is rejected (reason counted)."""
        rows = self.process_message(msg, imu=True)
        return rows[0].output(0) if rows else None

    def process_message(self, msg: Any, imu: bool = True, log_ns: int = 0) -> list[Rows]:
        """One IMU (``imu``) or magnetometer message object, logged at ``log_ns`` [ns], as a
        chunk of one event (:func:`process`): the outputs of the IMU message (none when it is
        rejected, or for a magnetometer message). A malformed message is counted
        (``malformed`` / ``mag_invalid``), never raised."""
        try:
            ev = (imu_message_events(msg, log_ns) if imu else
                  mag_message_events(msg, log_ns))
        except Exception:  # noqa: BLE001 - malformed: counted, never raised
            if imu:
                self.tally.received_imu += 1
                self.reject(checks.MALFORMED)
            else:
                self.tally.received_mag += 1
                self.tally.mag_invalid += 1
            return []
        return self.process(ev)

    def process(self, events: Events, start: int = 0, stop: int | None = None) -> list[Rows]:
        """Events ``start``..``stop`` (log order) through the pipeline's rules at once
        (:mod:`cf_estimator.pipeline.process`): the outputs of the IMU messages processed."""
        return process(self, events, start, stop)

    def note_internal_error(self) -> None:
        """Count the IMU message an unexpected exception (a bug) dropped, and keep the
        exception's traceback for :meth:`take_internal_error` (at most one per
        INTERNAL_ERROR_REPORT_S). Call from the ``except`` block."""
        self.reject(checks.INTERNAL_ERROR)
        now = perf_counter()
        if now - self._internal_error_at >= INTERNAL_ERROR_REPORT_S:
            self._internal_error_at = now
            self.internal_error_traceback = traceback.format_exc()

    def take_internal_error(self) -> str | None:
        """The traceback of an unexpected exception (a bug: the message was dropped and counted
        as ``internal_error``), at most one per INTERNAL_ERROR_REPORT_S; None when there is none
        to report. The node logs it, the replay prints it: once, not once per message."""
        text, self.internal_error_traceback = self.internal_error_traceback, None
        return text

    # -- diagnostics ------------------------------------------------------------------------------
    def diagnostics(self, now_s: float | None = None) -> DiagnosticsReport:
        """The report of the period since the last call (then a new period starts).

        ``now_s``: the current time on the clock of the header stamps (the node passes its
        clock's now); used for the period length and ``stamp_age_s``. Without it (replay) the
        figures come from stamps and counters only.
        """
        counters = self.counters
        period = None
        if now_s is not None and self._previous_now_s is not None:
            period = now_s - self._previous_now_s
        stamp_age = None
        if now_s is not None and self.clock.last_ns is not None:
            stamp_age = now_s - self.clock.last_ns * 1e-9
        mag_age = None
        if self.mag_input.last_used_ns is not None and self.clock.last_ns is not None:
            mag_age = (self.clock.last_ns - self.mag_input.last_used_ns) * 1e-9
        initialized = self._filter.initialized
        report = compose_report(
            name=self.diagnostics_name,
            hardware_id=self.imu_frame or "",
            counters=counters,
            previous=self._previous_counters,
            window=self.window,
            status=self._filter.status() if initialized else None,
            initialized=initialized,
            world_frame=self._fp.world_frame,
            use_mag=self._fp.use_mag,
            rpy_rad=self.last_rpy if initialized else None,
            input_warnings=dict(self._warned),
            period_s=period,
            stamp_age_s=stamp_age,
            mag_age_s=mag_age,
            mag_timeout_s=self._pp.mag_timeout_s,
            filter_backend=self._filter.backend,
            imu_topic=self.imu_topic,
        )
        if self._aiding is not None:
            report = dataclasses.replace(
                report, values=list(report.values) + velocity_values(
                    self._aiding.status(self.clock.last_ns * 1e-9 if self.clock.last_ns else None)))
        self._previous_counters = counters
        self._previous_now_s = now_s
        self.window = WindowStats()
        return report
