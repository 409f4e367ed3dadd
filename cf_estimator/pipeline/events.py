"""The pipeline's input: IMU, magnetometer, velocity and other messages in log order, as arrays.

A replay hands the pipeline a chunk of thousands of decoded messages; the live node hands it one
message at a time. Both arrive as :class:`Events`: ``kind`` per event (:data:`IMU`, :data:`MAG`,
:data:`VELOCITY`, :data:`OTHER`), its log time, and its row in a block of decoded messages (the
column layout of :mod:`cf_estimator.pipeline.columns`). :func:`imu_message_events` and
:func:`mag_message_events` make the one-event chunk of a message object (rclpy's or rosbags').
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from cf_estimator.pipeline import columns

IMU, MAG, OTHER, VELOCITY = 0, 1, 2, 3  #: event kinds; OTHER (e.g. a reference) passes through


class MessageRows:
    """Decoded messages of one type (row k = message k): ``values`` (n, 37 | 12) float64 in the
    layout of :mod:`cf_estimator.pipeline.columns`, header ``frame`` per row, and through
    :meth:`arrays` the header stamps (``sec``, ``nanosec``) and ``plain`` (the row holds the
    message; False: ask :attr:`Events.message` for the object). The bag readers' blocks
    (``bag/cdr.Block``) have the same shape."""

    __slots__ = ("frame", "n", "values", "_arrays")

    def __init__(self, values: np.ndarray, sec: np.ndarray, nsec: np.ndarray,
                 frame: list[Any]) -> None:
        self.values = values
        self.n = int(values.shape[0])
        self.frame = frame
        self._arrays = (sec, nsec, np.ones(self.n, dtype=bool))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``sec``, ``nanosec`` (int64) and ``plain`` (bool) per row."""
        return self._arrays


class Events:
    """Consecutive messages in log order: ``kind[i]``, ``log_ns[i]`` [ns] and ``row[i]`` (its row
    in ``imu`` or ``mag``, blocks with ``values``, ``frame`` and ``arrays()`` as
    :class:`MessageRows`); ``message(i)``: event i as a message object (rows that are not plain,
    velocity messages). ``arrays``: ``kind``, ``log_ns``, ``row`` as NumPy arrays when the reader
    has them."""

    def __init__(self, kind: Sequence[int], log_ns: Sequence[int], row: Sequence[int],
                 imu: Any, mag: Any, message: Callable[[int], Any],
                 arrays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> None:
        self.kind, self.log_ns, self.row = kind, log_ns, row
        self.imu, self.mag, self.message = imu, mag, message
        self._arrays = arrays

    def __len__(self) -> int:
        return len(self.kind)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``kind`` (int8), ``log_ns`` (int64), ``row`` (intp) as arrays (made once)."""
        if self._arrays is None:
            self._arrays = (np.asarray(self.kind, dtype=np.int8),
                            np.asarray(self.log_ns, dtype=np.int64),
                            np.asarray(self.row, dtype=np.intp))
        return self._arrays


_ONE_KIND = {k: np.array([k], dtype=np.int8) for k in (IMU, MAG)}
_ROW0 = np.zeros(1, dtype=np.intp)


def _one(kind: int, log_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arrays of a one-event chunk."""
    return _ONE_KIND[kind], np.array([log_ns], dtype=np.int64), _ROW0


def _no_message(i: int) -> Any:
    raise IndexError(i)


def _stamp(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    st = msg.header.stamp
    return np.array([int(st.sec)], dtype=np.int64), np.array([int(st.nanosec)], dtype=np.int64)


def _frame_id(msg: Any) -> str:
    frame = msg.header.frame_id
    if not isinstance(frame, str):
        raise TypeError(f"header.frame_id must be a string, got {type(frame).__name__}")
    return frame


def _covariance(cov: Any) -> list[float]:
    """A 9-element covariance (array.array, NumPy or a sequence) as floats."""
    c = cov.tolist() if hasattr(cov, "tolist") else [float(x) for x in cov]
    if len(c) != 9:
        raise ValueError(f"covariance must have 9 elements, got {len(c)}")
    return c


#: the orientation columns of an input row (unused by the pipeline: it computes its own)
_NO_ORIENTATION = [0.0] * (columns.ANGULAR_VELOCITY.start)


def imu_message_events(msg: Any, log_ns: int = 0) -> Events:
    """The one-event chunk of a sensor_msgs/Imu-like message logged at ``log_ns`` [ns].
    AttributeError, TypeError or ValueError when it is malformed (a field missing, not a
    number, a covariance not of 9)."""
    sec, nsec = _stamp(msg)
    frame = _frame_id(msg)
    av, la = msg.angular_velocity, msg.linear_acceleration
    values = np.array([_NO_ORIENTATION + [float(av.x), float(av.y), float(av.z)]
                       + _covariance(msg.angular_velocity_covariance)
                       + [float(la.x), float(la.y), float(la.z)]
                       + _covariance(msg.linear_acceleration_covariance)], dtype=np.float64)
    return Events((IMU,), (log_ns,), (0,), MessageRows(values, sec, nsec, [frame]), None,
                  _no_message, _one(IMU, log_ns))


def mag_message_events(msg: Any, log_ns: int = 0) -> Events:
    """The one-event chunk of a sensor_msgs/MagneticField-like message (AttributeError,
    TypeError or ValueError when it is malformed)."""
    sec, nsec = _stamp(msg)
    frame = _frame_id(msg)
    m = msg.magnetic_field
    values = np.zeros((1, columns.MAG_DOUBLES))
    m0 = columns.MAGNETIC_FIELD.start
    values[0, m0], values[0, m0 + 1], values[0, m0 + 2] = float(m.x), float(m.y), float(m.z)
    return Events((MAG,), (log_ns,), (0,), None, MessageRows(values, sec, nsec, [frame]),
                  _no_message, _one(MAG, log_ns))
