"""The pipeline's input: IMU, magnetometer, velocity and other messages in log order, as arrays.

A replay hands the pipeline a chunk of thousands of decoded messages; the live node hands it one
message at a time. Both arrive as :class:`Events`: ``kind`` per event (:data:`IMU`, :data:`MAG`,
:data:`VELOCITY`, :data:`OTHER`), its log time, and its row in a block of decoded messages (the
column layout of :mod:`cf_estimator.pipeline.columns`). :func:`imu_message_events` and
:func:`mag_message_events` make the one-event chunk of a message object (rclpy's or rosbags'),
:func:`message_events` one chunk of many message objects.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from cf_estimator.pipeline import columns
from cf_estimator.pipeline.messages import covariance9, stamp_of, vector3

IMU, MAG, OTHER, VELOCITY = 0, 1, 2, 3  #: event kinds; OTHER (e.g. a reference) passes through


_PLAIN_ONE = np.ones(1, dtype=bool)
_PLAIN_ONE.flags.writeable = False


class MessageRows:
    """Decoded messages of one type (row k = message k): ``values`` (n, 37 | 12) float64 in the
    layout of :mod:`cf_estimator.pipeline.columns`, header ``frame`` per row, and through
    :meth:`arrays` the header stamps (``sec``, ``nanosec``) and ``plain`` (the row holds the
    message; False: ask :attr:`Events.message` for the object). The bag readers' blocks
    (``bag/cdr.Block``) have the same shape."""

    __slots__ = ("frame", "n", "values", "_arrays")

    def __init__(self, values: np.ndarray, sec: np.ndarray, nsec: np.ndarray,
                 frame: list[Any], plain: np.ndarray | None = None) -> None:
        self.values = values
        self.n = int(values.shape[0])
        self.frame = frame
        if plain is None:  # every row holds its message
            plain = _PLAIN_ONE if self.n == 1 else np.ones(self.n, dtype=bool)
        self._arrays = (sec, nsec, plain)

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


def _frame_id(msg: Any) -> str:
    frame = msg.header.frame_id
    if not isinstance(frame, str):
        raise TypeError(f"header.frame_id must be a string, got {type(frame).__name__}")
    return frame


#: the orientation columns of an input row (unused by the pipeline: it computes its own)
_NO_ORIENTATION = (0.0,) * columns.ANGULAR_VELOCITY.start


def _imu_row(msg: Any) -> tuple[tuple[float, ...], int, int, str]:
    """A sensor_msgs/Imu-like message's row (columns.IMU_DOUBLES values), header stamp (sec,
    nanosec) and frame id; AttributeError, TypeError or ValueError when it is malformed (a
    field missing, not a number, a covariance not of 9)."""
    sec, nsec = stamp_of(msg)
    frame = _frame_id(msg)
    return (_NO_ORIENTATION + vector3(msg.angular_velocity)
            + covariance9(msg.angular_velocity_covariance) + vector3(msg.linear_acceleration)
            + covariance9(msg.linear_acceleration_covariance), sec, nsec, frame)


def _mag_row(msg: Any) -> tuple[tuple[float, ...], int, int, str]:
    """A sensor_msgs/MagneticField-like message's row (columns.MAG_DOUBLES values), stamp and
    frame id (AttributeError, TypeError or ValueError when it is malformed)."""
    sec, nsec = stamp_of(msg)
    frame = _frame_id(msg)
    return vector3(msg.magnetic_field) + _NO_MAG_COVARIANCE, sec, nsec, frame


_NO_MAG_COVARIANCE = (0.0,) * (columns.MAG_DOUBLES - columns.MAGNETIC_FIELD.stop)


def _rows(made: list[tuple[tuple[float, ...], int, int, str] | None], width: int
          ) -> MessageRows:
    """Rows made by :func:`_imu_row`/:func:`_mag_row` (None: malformed, not plain)."""
    zero = (0.0,) * width
    values = np.array([r[0] if r else zero for r in made], dtype=np.float64).reshape(-1, width)
    sec = np.array([r[1] if r else 0 for r in made], dtype=np.int64)
    nsec = np.array([r[2] if r else 0 for r in made], dtype=np.int64)
    plain = np.array([r is not None for r in made], dtype=bool)
    return MessageRows(values, sec, nsec, [r[3] if r else "" for r in made], plain)


def imu_message_events(msg: Any, log_ns: int = 0) -> Events:
    """The one-event chunk of a sensor_msgs/Imu-like message logged at ``log_ns`` [ns].
    AttributeError, TypeError or ValueError when it is malformed."""
    row, sec, nsec, frame = _imu_row(msg)
    return Events((IMU,), (log_ns,), (0,),
                  MessageRows(np.array([row], dtype=np.float64), np.array([sec]),
                              np.array([nsec]), [frame]), None, _no_message, _one(IMU, log_ns))


def mag_message_events(msg: Any, log_ns: int = 0) -> Events:
    """The one-event chunk of a sensor_msgs/MagneticField-like message (AttributeError,
    TypeError or ValueError when it is malformed)."""
    row, sec, nsec, frame = _mag_row(msg)
    return Events((MAG,), (log_ns,), (0,), None,
                  MessageRows(np.array([row], dtype=np.float64), np.array([sec]),
                              np.array([nsec]), [frame]), _no_message, _one(MAG, log_ns))


def message_events(items: Sequence[tuple[int, int, Any]]) -> Events:
    """Message objects ``(kind, log_ns, msg)`` in log order as one chunk: the IMU and
    magnetometer messages as rows (a malformed one is left to :attr:`Events.message`, where
    the pipeline counts it), the others as objects."""
    made: dict[int, list[tuple[tuple[float, ...], int, int, str] | None]] = {IMU: [], MAG: []}
    row = []
    for kind, _log_ns, msg in items:
        rows = made.get(kind)
        if rows is None:
            row.append(0)
            continue
        row.append(len(rows))
        try:
            rows.append(_imu_row(msg) if kind == IMU else _mag_row(msg))
        except Exception:  # noqa: BLE001 - malformed: the pipeline counts it from the object
            rows.append(None)
    return Events([k for k, _t, _m in items], [t for _k, t, _m in items], row,
                  _rows(made[IMU], columns.IMU_DOUBLES), _rows(made[MAG], columns.MAG_DOUBLES),
                  lambda i: items[i][2])
