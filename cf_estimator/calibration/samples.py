"""The magnetometer samples of a recording, as the replay reads them (any reader
:func:`cf_estimator.bag.io.open_bag` has: ROS 1/2 bags, PX4 ulogs, and whatever it learns).

The samples are the ``sensor_msgs/MagneticField`` vectors exactly as the replay hands them to
the pipeline: the message axes (the sensor frame, before any ``body_frame`` turn), Tesla for
ROS messages and ulogs (Gauss × 1e-4). A calibration fitted on them is applied to the same
vectors by the node, the replay and ``estimate``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cf_estimator.bag import io


@dataclass
class MagSamples:
    """``field_t``: (N, 3) magnetometer vectors [T, message axes]; ``t_s``: (N,) log times [s];
    ``topic``: where they came from; ``parameters``: the log's autopilot parameters, if any
    (PX4 ulogs: ``CAL_MAG*``); ``notes``: what the reader said about the log."""

    field_t: np.ndarray
    t_s: np.ndarray
    topic: str
    parameters: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    mag_bias_text: str = ""


def read_mag_samples(path: str | os.PathLike[str], topic: str | None = None, *,
                     instance: int | None = None) -> MagSamples:
    """Every magnetometer message of ``path`` (``topic``: which one when the log has several;
    auto-detected like ``replay --mag-topic``). :class:`cf_estimator.bag.io.BagError` (one
    line naming the file) when it cannot be read or has no magnetometer."""
    with io.open_bag(path, ulog_instance=instance) as bag:
        name = bag.select_topic("magnetometer", topic, [io.MAG_TYPE], required=True,
                                option="--mag-topic")
        assert name is not None
        rows = []
        stamps = []
        for bm in bag.messages([name], bulk=True):
            f = bm.msg.magnetic_field
            rows.append((float(f.x), float(f.y), float(f.z)))
            stamps.append(bm.log_time_ns)
        params = dict(getattr(bag, "parameters", None) or {})
        notes = list(getattr(bag, "notes", None) or [])
        bias_text = str(getattr(bag, "mag_bias_text", "") or "")
    return MagSamples(np.array(rows, dtype=float).reshape(-1, 3),
                      np.array(stamps, dtype=np.int64) * 1e-9, name, params, notes, bias_text)
