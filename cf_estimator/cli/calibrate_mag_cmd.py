"""``cf-estimator calibrate-mag LOG``: fit the magnetometer's hard and soft iron on a recording
and write the parameters the node, the replay and ``estimate`` apply before the filter.

The samples are read as the replay reads them (:mod:`cf_estimator.calibration.samples`), the
fit is :mod:`cf_estimator.calibration.magfit`; this module only parses, prints and writes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from cf_estimator.cli.base import CliError
from cf_estimator.cli.common import check_input_path, check_output_file, note

#: What the output file holds: the two parameters of the calibration, nothing else.
WRITTEN = ("mag_hard_iron_t", "mag_soft_iron")


def register(subparsers: Any) -> None:
    """Add the ``calibrate-mag`` sub-command to ``subparsers``."""
    p = subparsers.add_parser(
        "calibrate-mag",
        help="fit the magnetometer's hard and soft iron on a recording (bag, ulog)",
        description=(
            "Fit the magnetometer calibration (hard iron, then soft iron when the recording "
            "turns the sensor through enough of the sphere) on the magnetometer samples of a "
            "recording (ROS 1/2 bag, PX4 ulog: whatever replay reads), print the coverage and "
            "the residual, and write mag_hard_iron_t / mag_soft_iron as a ROS 2 parameter file "
            "to pass after the node's own (--params-file twice; replay --params takes one file: "
            "copy the two lines into it). Refuses, in one line, a recording that cannot "
            "support the fit."),
    )
    p.add_argument("log", metavar="LOG", help="bag (.bag, ROS 2 bag directory) or PX4 .ulg")
    p.add_argument("-o", "--output", metavar="YAML",
                   help="write the parameters to this file (default: print them)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --output")
    p.add_argument("--mag-topic", metavar="TOPIC",
                   help="the magnetometer topic (default: the only sensor_msgs/MagneticField)")
    p.add_argument("--instance", type=int, metavar="N",
                   help="ulog: the multi_id of a topic with several instances")
    p.add_argument("--hard-iron-only", action="store_true",
                   help="fit the offset alone (a sphere; soft iron identity): needs less of the "
                   "sphere (30%% instead of 60%%)")
    p.add_argument("--start", type=float, metavar="S", default=None,
                   help="use samples from this many seconds after the first one")
    p.add_argument("--end", type=float, metavar="S", default=None,
                   help="use samples up to this many seconds after the first one")
    p.set_defaults(run=run)


def _vec_ut(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x * 1e6:+.2f}" for x in v) + ") uT"


def _matrix(s: np.ndarray) -> str:
    return "[" + "; ".join(" ".join(f"{x:+.4f}" for x in row) for row in s) + "]"


def render_yaml(hard_iron_t: np.ndarray, soft_iron: np.ndarray, comment: str) -> str:
    """The parameter file of a calibration (``/**`` section, the two parameters only)."""
    from cf_estimator.params_file import render_params_yaml
    from cf_estimator.pipeline.params import PipelineParams

    pp = PipelineParams(mag_hard_iron_t=tuple(float(x) for x in hard_iron_t),
                        mag_soft_iron=tuple(float(x) for x in np.asarray(soft_iron).ravel()))
    return f"# {comment}\n" + render_params_yaml(pipeline_params=pp, only=WRITTEN)


def run(args: argparse.Namespace) -> int:
    """Read, fit, print, write; CliError (one line) for what cannot be done."""
    from cf_estimator.bag.io import BagError
    from cf_estimator.calibration import magfit
    from cf_estimator.calibration.autopilot import px4_calibration
    from cf_estimator.calibration.samples import read_mag_samples

    check_input_path(args.log, "recording")
    check_output_file(args.output, overwrite=args.overwrite, option="--output")
    try:
        samples = read_mag_samples(args.log, args.mag_topic, instance=args.instance)
    except BagError as exc:
        raise CliError(str(exc).splitlines()[0], getattr(exc, "code", 1)) from None
    for text in samples.notes:
        note(text)
    m, t = samples.field_t, samples.t_s
    if t.size:
        rel = t - t[0]
        keep = np.ones(t.shape[0], dtype=bool)
        if args.start is not None:
            keep &= rel >= args.start
        if args.end is not None:
            keep &= rel <= args.end
        m, t = m[keep], t[keep]
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    print(f"{args.log}: {samples.topic}, {m.shape[0]} magnetometer samples over {span:.1f} s")
    auto = px4_calibration(samples.parameters)
    if auto is not None:
        print(f"  autopilot's own calibration, already applied to these samples: {auto.source}: "
              f"offset {_vec_ut(auto.hard_iron_t)}, scale {_matrix(auto.soft_iron)}")
    if samples.mag_bias_text:
        print(f"  {samples.mag_bias_text}")
    try:
        cal = magfit.fit(m, hard_iron_only=args.hard_iron_only)
    except magfit.CalibrationError as exc:
        raise CliError(f"{args.log}: cannot calibrate: {exc}", 1) from None
    print(f"  coverage {cal.coverage:.0%} of the sphere; field {cal.field * 1e6:.2f} uT; "
          f"residual {cal.residual:.2%} of the field RMS ({cal.model}; the sphere alone: "
          f"{cal.sphere_residual:.2%})")
    share = np.linalg.norm(cal.hard_iron) / cal.field
    print(f"  mag_hard_iron_t {_vec_ut(cal.hard_iron)} ({share:.1%} of the field)")
    print(f"  mag_soft_iron {_matrix(cal.soft_iron)}")
    if auto is not None:
        print(f"  (what remains after the autopilot's calibration: a hard iron of "
              f"{np.linalg.norm(cal.hard_iron) / cal.field:.1%} of the field)")
    text = render_yaml(cal.hard_iron, cal.soft_iron,
                       f"cf-estimator calibrate-mag {args.log} ({samples.topic}): coverage "
                       f"{cal.coverage:.0%}, residual {cal.residual:.2%}, {cal.model}")
    if args.output is None:
        sys.stdout.write(text)
    else:
        from cf_estimator.bag.io import write_atomic_text

        write_atomic_text(Path(args.output), text)
        print(f"  wrote {args.output}: add it after the node's parameters "
              f"(--params-file base.yaml --params-file {args.output})")
    return 0
