"""``cf-estimator replay``: run recorded bags through the node's pipeline, without ROS.

Input: a ROS 1 ``.bag`` or a ROS 2 bag directory (sqlite3 or mcap). Output: a ROS 2 bag
(Jazzy definitions) with ``/imu/data``, ``/imu/rpy`` and ``/diagnostics`` as the live node
publishes them, optionally the input topics (``--copy-inputs``); a JSON summary; PNG plots.
Several bags, or a directory of them (a fleet, :mod:`cf_estimator.bag.fleet`): one output per
bag under ``-o DIR``, a table and one JSON with every bag; ``--cluster`` runs them on Dask.
See docs/replay.md and docs/cluster.md.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from cf_estimator.bag import io
from cf_estimator.bag.replay import HEADING_ALIGNMENTS, ReplayError, ReplayOptions, replay_bag
from cf_estimator.cli.base import EXIT_ALL_FAILED, EXIT_OK, EXIT_SOME_FAILED, CliError
from cf_estimator.cli.common import (
    add_params_options,
    check_input_path,
    check_output_dir,
    check_output_file,
    load_params,
    warn,
)


def register(subparsers: Any) -> None:
    """Add the ``replay`` sub-command to ``subparsers``."""
    p = subparsers.add_parser(
        "replay",
        help="replay a ROS 1/ROS 2 bag, a PX4 ulog or an ArduPilot DataFlash log through the "
             "estimator (no ROS needed)",
        description=(
            "Replay a recorded bag (ROS 1 .bag, or ROS 2 bag directory with sqlite3 or mcap "
            "storage) through exactly the node's processing and write a ROS 2 bag with its "
            "output topics /imu/data, /imu/rpy and /diagnostics (same types and stamps as the "
            "live node), a JSON summary and plots. IMU and magnetometer topics are detected by "
            "message type when there is exactly one of each. A PX4 ulog (.ulg) is read like a "
            "bag: sensor_combined, vehicle_magnetometer (or sensor_combined's magnetometer), "
            "vehicle_local_position for --velocity-topic; the output follows PX4's conventions "
            "(FRD body -> NED, stamps = log time since boot) and is compared with the log's "
            "vehicle_attitude (agreement with the autopilot, not ground truth). An ArduPilot "
            "DataFlash log (.bin, read with pymavlink) likewise: IMU, MAG, compared with ATT "
            "(and AHR2, EKF1, NKF1, XKF1 where logged)."
        ),
    )
    p.add_argument("bag", metavar="BAG", nargs="+",
                   help="input bag: ROS 1 .bag file, ROS 2 bag directory or .mcap file, PX4 "
                   ".ulg log or ArduPilot .bin log; "
                   "several, or a directory of them (searched recursively, mixed), replay a "
                   "fleet: one output per bag, a summary table and one JSON")
    p.add_argument("-o", "--output", metavar="OUT",
                   help="output ROS 2 bag directory (written atomically; see --overwrite); for "
                   "a fleet, the directory that receives one bag per input, OUT/<name>")
    add_params_options(p, "the one the node reads with --params-file")
    p.add_argument("--imu-topic", metavar="TOPIC", help="sensor_msgs/Imu input (default: detect)")
    p.add_argument("--mag-topic", metavar="TOPIC",
                   help="sensor_msgs/MagneticField input (default: detect; 'none' = without)")
    p.add_argument("--velocity-topic", metavar="TOPIC",
                   help="velocity aiding input: geometry_msgs/TwistStamped (world-frame "
                        "velocity, axes by the velocity_frame parameter) or nav_msgs/Odometry "
                        "(default: none, IMU-only)")
    p.add_argument("--reference-topic", metavar="TOPIC",
                   help="orientation reference (geometry_msgs/PoseStamped, QuaternionStamped, "
                        "nav_msgs/Odometry, or a sensor_msgs/Imu's orientation): adds error "
                        "statistics")
    p.add_argument("--instance", type=int, metavar="N",
                   help="PX4 ulog: the instance (multi_id) to use of a topic logged several "
                        "times, e.g. a second magnetometer; ArduPilot log: the IMU and MAG "
                        "instance (IMU2, MAG2 = 1; default: the lowest, said)")
    p.add_argument("--heading-alignment", choices=HEADING_ALIGNMENTS, default="auto",
                   help="unknown constant heading offset of the reference: none, first (match the "
                        "first scored sample), mean (circular mean); auto = none with a "
                        "magnetometer, first without (default)")
    p.add_argument("--offline", action="store_true",
                   help="write the offline (acausal) estimate: every sample uses the whole "
                   "recording (forward and backward passes; docs/offline.md); same topics, "
                   "marked offline in the JSON summary and the bag's metadata")
    p.add_argument("--storage", choices=sorted(io.STORAGES), default="mcap",
                   help="output storage plugin (default mcap)")
    p.add_argument("--copy-inputs", action="store_true",
                   help="also write the input topics used (IMU, magnetometer, reference)")
    p.add_argument("--plot", metavar="DIR",
                   help="write PNG plots into DIR (created; an existing DIR needs --overwrite)")
    p.add_argument("--json", metavar="FILE", help="write the JSON summary to FILE ('-' = stdout)")
    p.add_argument("--csv", metavar="FILE",
                   help="write the per-sample results to FILE (one row per IMU message: stamp, "
                   "quaternion, roll/pitch/yaw, variances, gyro bias, flags, the reference "
                   "where there is one; cf_estimator/bag/csvout.py); one input only")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing output bag and JSON file, write into an existing "
                   "plot directory")
    from cf_estimator.cluster import add_cluster_option

    add_cluster_option(p)
    prog = p.add_mutually_exclusive_group()
    prog.add_argument("--progress", dest="progress", action="store_true", default=None,
                      help="always show a progress bar on stderr")
    prog.add_argument("--no-progress", dest="progress", action="store_false",
                      help="never show a progress bar (default: only when stderr is a terminal)")
    p.set_defaults(run=run)


def write_json(target: str, data: dict[str, Any]) -> None:
    text = json.dumps(data, indent=2, allow_nan=False) + "\n"
    if target == "-":
        sys.stdout.write(text)
    else:
        io.write_atomic_text(Path(target), text)


def _format_counts(d: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in d.items()) if d else "none"


def mag_line(s: dict[str, Any]) -> str:
    """``mag     N received: used U, rejected R (disturbed field), stale S, ...``."""
    c = s.get("counters") or {}
    if not s["topics"].get("mag"):
        return "mag     none: heading from the gyro alone (6-D; yaw drifts)"
    if c.get("mag_disabled", 0) and not c.get("mag_used", 0):
        return (f"mag     {c.get('received_mag', 0)} received, not used (use_mag false): "
                "heading from the gyro alone")
    return (f"mag     {c.get('received_mag', 0)} received: used {c.get('mag_used', 0)}, "
            f"rejected {c.get('mag_rejected', 0)} (disturbed field), stale "
            f"{c.get('mag_stale', 0)}, invalid {c.get('mag_invalid', 0)}, superseded "
            f"{c.get('mag_dropped', 0)}")


def velocity_line(s: dict[str, Any]) -> str:
    """``velocity N on TOPIC: used U, stale S, rejected ...; aided A IMU samples (share,
    share aided horizontally; from T s after the first velocity; aligned at T s); heading
    ...``."""
    v = s["velocity"]
    topic = s["topics"].get("velocity")
    if "used" not in v:
        return f"velocity {v['messages_in']} on {topic}: none usable (aiding off)"
    offset, sigma = v.get("heading_offset_rad"), v.get("heading_sigma_rad")
    heading = (f"heading offset {math.degrees(offset):+.1f} deg ± {math.degrees(sigma):.1f}"
               if sigma is not None and offset is not None else "heading offset not observed")
    to_aid, to_align = v.get("time_to_aid_s"), v.get("time_to_align_s")
    began = (f" ({100.0 * v['aided_fraction']:.0f} %, horizontally "
             f"{100.0 * v['aided_horizontal_fraction']:.0f} %; from {to_aid:.1f} s after the "
             "first velocity" + (f"; aligned at {to_align:.1f} s" if to_align is not None else "")
             + ")" if to_aid is not None else "")
    return (f"velocity {v['messages_in']} on {topic}: used {v['used']}, stale {v['stale']}, "
            f"rejected {sum(v['rejected'].values())} ({_format_counts(v['rejected'])}); aided "
            f"{v['aided_samples']} IMU samples{began}; {heading}"
            f"{'' if v['heading_known'] else ' (not known: no aiding)'}")


#: Below this share of magnetometer samples used, the replay warns that heading was mostly
#: unreferenced (it followed the gyro).
MAG_USED_WARN_FRACTION = 0.5


def heading_warning(s: dict[str, Any]) -> str | None:
    """A warning when the magnetometer referenced heading for less than half its samples."""
    c = s.get("counters") or {}
    received = int(c.get("received_mag", 0))
    used = int(c.get("mag_used", 0))
    if not s["topics"].get("mag") or received == 0 or c.get("mag_disabled", 0) >= received:
        return None
    if used >= MAG_USED_WARN_FRACTION * received:
        return None
    return (f"heading was mostly unreferenced: the magnetometer corrected it with only {used} "
            f"of {received} samples ({100.0 * used / received:.0f} %; rejected "
            f"{c.get('mag_rejected', 0)}, stale {c.get('mag_stale', 0)}); in between yaw "
            "follows the gyro (see mag_rejection, mag_field_tolerance)")


def autopilot_line(ref: dict[str, Any]) -> str:
    """``px4 vs vehicle_attitude``: roll, pitch, yaw, inclination RMS / max [deg], labelled as
    agreement with the autopilot's estimate (not ground truth)."""
    if not ref.get("rmse_deg"):
        return (f"autopilot vs {ref['topic']}: no sample of the autopilot's estimate overlaps "
                "ours")
    rms, mx = ref["rpy_rmse_deg"], ref["rpy_max_deg"]
    parts = [f"{k} {rms[k]:.3f}/{mx[k]:.3f}" for k in ("roll", "pitch", "yaw")]
    parts.append(f"inclination {ref['rmse_deg']['inclination']:.3f}/"
                 f"{ref['max_deg']['inclination']:.3f}")
    return (f"autopilot {ref['label']}, {ref['samples_scored']} samples of {ref['topic']}: "
            f"RMS/max [deg] {', '.join(parts)}")


def ardupilot_lines(x: dict[str, Any]) -> list[str]:
    """The ``ardupilot`` lines of the summary: vehicle, frames and conventions, magnetometer,
    and where the comparison ends before a flip or crash."""
    lines = [f"ardupilot {x.get('vehicle') or 'vehicle not named in the log'}: output "
             f"{x['output_frames']} (ArduPilot conventions: "
             f"{', '.join(x['conventions_applied']) or 'as set'}); stamps: log time since boot"]
    if x.get("magnetometer"):
        lines.append(f"          {x['magnetometer']}")
    if x.get("scored_until_s") is not None:
        lines.append(f"          upside down at {x['upside_down_s']:.1f} s (flip or crash): "
                     f"compared up to {x['scored_until_s']:.1f} s")
    return lines


def _fmt(value: Any, spec: str, missing: str = "n/a") -> str:
    """``value`` formatted with ``spec``; ``missing`` for None, NaN or Inf (a summary figure
    that could not be computed must not stop the summary)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return missing
    return format(value, spec)


def covariance_line(cov: dict[str, Any]) -> str | None:
    """``covariance`` line of the summary: the reported σ against the reference's errors after
    settle_s (share beyond 2σ, mean(e²/σ²); a consistent Gaussian: tilt 1.8 %, heading 4.6 %,
    mean 1; for the tilt also the share beyond twice its per-axis σ, consistent 13.5 %), or None
    when nothing was scored."""
    from cf_estimator.bench.consistency import CONSISTENT_BEYOND

    parts = []
    for name, sigma2 in (("tilt", "cov[0]+cov[4]"), ("heading", "cov[8]")):
        c = cov.get(name)
        if c:
            share = _fmt(c.get("beyond_2sigma_pct"), ".1f")
            axis = (f", per axis {_fmt(c.get('beyond_2sigma_axis_pct'), '.1f')} % (consistent "
                    f"{CONSISTENT_BEYOND['tilt per axis']})" if name == "tilt" else "")
            parts.append(f"{name} (σ² = {sigma2}) beyond 2σ {share} % (consistent "
                         f"{CONSISTENT_BEYOND[name]}){axis}, mean(e²/σ²) "
                         f"{_fmt(c.get('mean_ratio'), '.2f')} (consistent 1)")
    if not parts:
        return None
    return (f"covariance vs reference after {_fmt(cov.get('settle_s'), '.0f')} s: "
            + "; ".join(parts))


def print_summary(s: dict[str, Any], out: Any = None) -> None:
    """The human summary of one replay (to ``out``, default stdout). Every figure that may be
    None or NaN in the JSON prints as ``n/a``."""
    out = sys.stdout if out is None else out
    rate = s.get("imu_rate_hz")
    rate_text = f"{_fmt(rate, '.1f')} Hz" if rate else "n/a"
    topics = s["topics"]
    if s.get("mode") == "offline":
        print(f"mode    offline (acausal), {s['offline']['segments']} segment(s)", file=out)
    print(f"input   {s['input']} ({s['input_format']}): {s['messages_in']} IMU on "
          f"{topics['imu']}, {s['mag_messages_in']} mag on {topics['mag'] or '-'}, "
          f"{_fmt(s.get('duration_s'), '.1f')} s of stamps, {rate_text}", file=out)
    if s.get("px4"):
        x = s["px4"]
        print(f"px4     output {x['output_frames']} (PX4 conventions: "
              f"{', '.join(x['conventions_applied']) or 'as set'}); stamps: log time since "
              "boot", file=out)
    if s.get("ardupilot"):
        for line in ardupilot_lines(s["ardupilot"]):
            print(line, file=out)
    rej = s["messages_rejected"]
    print(f"pipeline processed {s['messages_processed']}, rejected "
          f"{sum(rej.values())} ({_format_counts(rej)}), gaps {s.get('gaps')}, resets "
          f"{_format_counts(s.get('resets') or {})}, clipped "
          f"{100.0 * (s['clipped_fraction'] or 0.0):.1f}% of samples", file=out)
    print(mag_line(s), file=out)
    if s.get("velocity") is not None:
        print(velocity_line(s), file=out)
    bias = s.get("final_gyro_bias_rad_s")
    if bias:
        after = s.get("gyro_bias_converged_after_s")
        learned = (f"converged {_fmt(after, '.1f')} s after start" if after is not None
                   else "not converged")
        print("bias    final gyro-bias estimate [rad/s]: "
              + " ".join(_fmt(b, "+.5f") for b in bias)
              + f" ± {_fmt(s.get('final_gyro_bias_sigma_rad_s'), '.5f')} ({learned}); still "
              f"{100.0 * (s.get('still_fraction') or 0.0):.0f}% of samples", file=out)
    if s.get("output"):
        print(f"output  {s['output']} ({s['storage']}): {_format_counts(s['outputs_written'])}",
              file=out)
    ref = s.get("reference")
    if ref and ref.get("kind") == "autopilot":
        print(autopilot_line(ref), file=out)
        for topic, e in ((s.get("ardupilot") or {}).get("estimates") or {}).items():
            if topic != ref.get("topic"):
                print(f"  vs {topic:<5} {e['samples_scored']} samples: inclination RMS/max "
                      f"{_fmt(e['inclination_rmse_deg'], '.3f')}/"
                      f"{_fmt(e['inclination_max_deg'], '.3f')} deg, heading RMS "
                      f"{_fmt(e['heading_rmse_deg'], '.3f')} deg", file=out)
    elif ref:
        rmse = ref.get("rmse_deg")
        if rmse:
            print(f"error   vs {ref['topic']} ({ref['samples_scored']} samples, heading "
                  f"alignment {ref['heading_alignment']}, offset "
                  f"{_fmt(ref.get('heading_offset_deg'), '.2f')} deg): RMSE total "
                  f"{_fmt(rmse.get('total'), '.3f')}, inclination "
                  f"{_fmt(rmse.get('inclination'), '.3f')}, heading "
                  f"{_fmt(rmse.get('heading'), '.3f')} deg", file=out)
        else:
            print(f"error   vs {ref['topic']}: no reference sample overlaps the estimate",
                  file=out)
    if ref and ref.get("covariance"):
        line = covariance_line(ref["covariance"])
        if line:
            print(line, file=out)
    print(f"speed   {_fmt(s.get('messages_per_s'), '.0f')} messages/s "
          f"({_fmt(s.get('wall_time_s'), '.2f')} s)", file=out)


def _is_fleet(args: argparse.Namespace) -> bool:
    """Several inputs, a directory that is not itself a bag, or --cluster."""
    if len(args.bag) > 1 or args.cluster is not None:
        return True
    p = Path(args.bag[0])
    if not p.is_dir() or (p / "metadata.yaml").is_file() or any(p.glob("*.mcap")) or \
            any(p.glob("*.db3")):
        return False
    from cf_estimator.bag.fleet import find_bags

    return bool(find_bags([p]))  # a directory without bags: the single-bag error says why


def _options(args: argparse.Namespace) -> ReplayOptions:
    from cf_estimator.params_file import explicit_names

    return ReplayOptions(
        instance=args.instance,
        explicit_params=explicit_names(args.params, args.node_name),
        imu_topic=args.imu_topic, mag_topic=args.mag_topic, reference_topic=args.reference_topic,
        storage=args.storage, copy_inputs=args.copy_inputs, overwrite=args.overwrite,
        heading_alignment=args.heading_alignment, progress=args.progress,
        offline=args.offline, velocity_topic=args.velocity_topic,
    )




def run_fleet(args: argparse.Namespace) -> int:
    """Replay several bags: one output each, a table, one JSON. Exit status
    (:mod:`cf_estimator.cli.base`): 0 every bag replayed, 1 some failed, 3 all failed."""
    from cf_estimator.bag import fleet
    from cf_estimator.cluster import ClusterError, make_engine

    for b in args.bag:
        check_input_path(b, "input bag")
    bags = fleet.find_bags(args.bag)
    if not bags:
        raise CliError(f"no bags found in {', '.join(args.bag)} (ROS 1 *.bag files or ROS 2 "
                       "bag directories with metadata.yaml)", 2)
    check_output_dir(args.output, overwrite=args.overwrite, option="-o")
    check_output_file(args.json, overwrite=args.overwrite, option="--json")
    check_output_dir(args.plot, overwrite=args.overwrite, option="--plot")
    fparams, pparams = load_params(args.params, args.node_name)
    opts = _options(args)
    if opts.storage not in io.STORAGES:
        raise CliError(f"unknown storage {opts.storage!r}", 2)
    tasks = fleet.make_tasks(bags, args.output, args.plot, fparams, pparams, opts)
    if args.output is not None:
        try:
            Path(args.output).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CliError(f"-o {args.output}: cannot create: {exc.strerror or exc}", 2) from None
    for t in tasks:
        if t.output is not None:
            try:
                io.check_output_path(Path(t.output), overwrite=args.overwrite,
                                     inputs=[Path(x.bag) for x in tasks])
            except io.BagError as exc:
                raise CliError(str(exc), exc.code) from None
    try:
        with make_engine(args.cluster) as engine:
            writable = [d for d in (args.output, args.plot) if d is not None]
            engine.check_paths([t.bag for t in tasks], writable=writable)
            result = fleet.replay_fleet(tasks, engine, progress=args.progress)
    except ClusterError as exc:
        raise CliError(str(exc), 2) from None
    for s in result["bags"]:
        _finish_summary(s, args, prefix=f"{s['name']}: ")
    if args.json is not None:
        write_json(args.json, result)
    if args.json != "-":
        print(fleet.format_table(result), end="")
        if args.json is not None:
            print(f"json    {args.json}")
    failed, replayed = result["fleet"]["failed"], result["fleet"]["replayed"]
    return EXIT_OK if not failed else (EXIT_SOME_FAILED if replayed else EXIT_ALL_FAILED)


def _finish_summary(summary: dict, args: argparse.Namespace, prefix: str = "") -> None:
    """The parameter file and node name into a replay summary, the heading warning added, and
    every warning printed once (``prefix``: the bag's name in a fleet)."""
    summary["params_file"] = args.params
    summary["node_name"] = args.node_name
    mag_warning = heading_warning(summary)
    if mag_warning:
        summary["warnings"].append(mag_warning)
    for text in summary["warnings"]:
        warn(f"{prefix}{text}")


def run(args: argparse.Namespace) -> int:
    if args.output is None and args.json is None and args.plot is None and args.csv is None:
        raise CliError("nothing to write: give -o OUT, --json FILE, --csv FILE or --plot DIR", 2)
    if _is_fleet(args):
        if args.csv is not None:
            raise CliError("--csv writes one input's samples: give one bag or log (a fleet "
                           "writes -o, --json and --plot)", 2)
        return run_fleet(args)
    args.bag = args.bag[0]
    check_input_path(args.bag, "input bag")
    check_output_file(args.json, overwrite=args.overwrite, option="--json")
    check_output_file(args.csv, overwrite=args.overwrite, option="--csv")
    check_output_dir(args.plot, overwrite=args.overwrite, option="--plot")
    if args.output is not None:
        try:
            io.check_output_path(Path(args.output), overwrite=args.overwrite,
                                 inputs=[Path(args.bag)])
        except io.BagError as exc:
            raise CliError(str(exc), exc.code) from None
    fparams, pparams = load_params(args.params, args.node_name)
    opts = _options(args)
    try:
        result = replay_bag(args.bag, args.output, fparams, pparams, opts)
    except io.BagError as exc:
        raise CliError(str(exc), exc.code) from None
    except ReplayError as exc:
        raise CliError(str(exc), 2) from None
    summary = result.summary
    _finish_summary(summary, args)
    try:
        if args.plot is not None:
            from cf_estimator.bag.plots import plot_replay

            paths = plot_replay(result, args.plot, title=Path(args.bag).name)
            summary["plots"] = [str(p) for p in paths]
        if args.csv is not None:
            from cf_estimator.bag.csvout import write_csv

            summary["csv"] = {"path": args.csv, "rows": write_csv(args.csv, result.series)}
        if args.json is not None:
            write_json(args.json, summary)
    except BaseException:  # no output bag without its summary: it would look complete
        if result.output is not None:
            import shutil

            shutil.rmtree(result.output, ignore_errors=True)
        raise
    if args.json != "-":
        print_summary(summary)
        if summary.get("plots"):
            print(f"plots   {', '.join(summary['plots'])}")
        if args.csv is not None:
            print(f"csv     {args.csv} ({summary['csv']['rows']} rows)")
        if args.json is not None:
            print(f"json    {args.json}")
    return 0
