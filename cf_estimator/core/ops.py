"""Arithmetic back-ends for the filter step: plain floats (one filter) or NumPy arrays (many).

The step in :mod:`cf_estimator.core.step` is written once, component by component, against
this small interface, so the single filter and the batched tuner run the same equations.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

SMALL_ANGLE_RAD = 1e-6
#: Smallest divisor of a norm [1]: a zero vector divides by this, never by zero.
TINY = 1e-300


def sq(x: Any) -> Any:
    """x·x: the square as a product, in both back-ends and in ``c/cf_core.c`` (``sq``). Python's
    ``x ** 2`` calls libm's ``pow``, which is not correctly rounded: about one input in a
    thousand differs from x·x in the last bit (GCC turns C's ``pow(x, 2.0)`` into x·x)."""
    return x * x


def rotation_elements(qw: Any, qx: Any, qy: Any, qz: Any) -> tuple[Any, ...]:
    """R(q) of a unit quaternion (w, x, y, z), row-major (r00, r01, … r22): plain arithmetic,
    floats and arrays alike, the operations of ``c/cf_core.c`` in the same order."""
    return (1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy),
            2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx),
            2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy))


class FloatOps:
    """Scalar back-end: Python floats and bools (fast for one 3-vector at a time)."""

    sqrt = staticmethod(math.sqrt)
    sin = staticmethod(math.sin)
    cos = staticmethod(math.cos)
    atan2 = staticmethod(math.atan2)

    @staticmethod
    def where(cond: Any, a: Any, b: Any) -> Any:
        """``a`` where ``cond`` else ``b``."""
        return a if cond else b

    @staticmethod
    def not_(a: Any) -> Any:
        """Logical not."""
        return not a

    @staticmethod
    def maximum(a: Any, b: Any) -> Any:
        """Element-wise maximum."""
        return a if a >= b else b

    @staticmethod
    def minimum(a: Any, b: Any) -> Any:
        """Element-wise minimum."""
        return a if a <= b else b

    @staticmethod
    def sin_half_over(angle: Any) -> Any:
        """sin(angle/2)/angle, finite at angle → 0 (used by the exponential map)."""
        if angle < SMALL_ANGLE_RAD:
            return 0.5 - angle * angle / 48.0
        return math.sin(0.5 * angle) / angle


class ArrayOps:
    """Vector back-end: NumPy arrays with a leading parameter-set axis."""

    sqrt = staticmethod(np.sqrt)
    sin = staticmethod(np.sin)
    cos = staticmethod(np.cos)
    atan2 = staticmethod(np.arctan2)
    where = staticmethod(np.where)
    not_ = staticmethod(np.logical_not)
    maximum = staticmethod(np.maximum)
    minimum = staticmethod(np.minimum)

    @staticmethod
    def sin_half_over(angle: Any) -> Any:
        """sin(angle/2)/angle, finite at angle → 0 (used by the exponential map)."""
        small = angle < SMALL_ANGLE_RAD
        safe = np.where(small, 1.0, angle)
        return np.where(small, 0.5 - angle * angle / 48.0, np.sin(0.5 * safe) / safe)
