"""``cf-estimator design``: loop parameters, exact peak errors and the thesis check for k1, k2.

Every design parameter defaults to the shipped one (``FilterParams()``: k1, k2, the saturation
level and the aperiodic time constant), so a bare ``design --thesis`` checks the filter as it
ships. Gains come from ``--k1/--k2`` or from the inverse ``--n N [--xi XI]`` / ``--period S
[--xi XI]`` (ξ = k1/n as in Ryzhkov & Karpenko; default 1, their choice). Accelerations are given
in g and converted with the papers' small-angle convention (a/g of 0.2 is an accelerometer angle
error of 0.2 rad); the thesis check uses atan(a/g). References: docs/references.md.
All formulas live in :mod:`cf_estimator.analysis.design`.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from cf_estimator.analysis import design, thesis
from cf_estimator.cli.base import CliError, finite_float
from cf_estimator.core.params import FilterParams
from cf_estimator.core.step import LOOP_LAG_FRACTION

#: Ryzhkov & Karpenko's example initial error [rad] for the clipped recovery time.
PAPER_INITIAL_ERROR_RAD = 0.1
SHIPPED = FilterParams()


def register(subparsers: Any) -> None:
    """Add the ``design`` sub-command to ``subparsers``."""
    p = subparsers.add_parser(
        "design",
        help="loop parameters, exact peak errors and the thesis check for gains k1, k2",
        description=(
            "Design formulas of the compensation scheme W(s) = k1 + k2/s (Ryzhkov & Karpenko): "
            "natural frequency n = sqrt(k2), damping xi = k1/n (theirs) and zeta = k1/(2n), "
            "period, settling time, exact peak errors next to the paper's rough formulas, "
            "saturation guidance and the requirement check of Habliuk's thesis (2023). Every "
            "value defaults to the shipped parameters."
        ),
    )
    f = finite_float
    gains = p.add_argument_group("gains (either k1/k2, or n or period with xi)")
    gains.add_argument("--k1", type=f, metavar="K1",
                       help=f"proportional gain [1/s] (default {SHIPPED.k1:g}, shipped)")
    gains.add_argument("--k2", type=f, metavar="K2",
                       help=f"integral gain [1/s^2] (default {SHIPPED.k2:g}, shipped)")
    inverse = gains.add_mutually_exclusive_group()
    inverse.add_argument("--n", type=f, metavar="N", help="natural frequency n [rad/s] -> k2 = n^2")
    inverse.add_argument("--period", type=f, metavar="S", help="natural period 2*pi/n [s]")
    gains.add_argument("--xi", type=f, metavar="XI",
                       help="damping xi = k1/n (Ryzhkov & Karpenko's), with --n/--period "
                       "(default 1) -> k1 = xi*n")
    ev = p.add_argument_group("disturbances (errors: exact vs the paper's rough formula)")
    ev.add_argument("--drift", type=f, metavar="RAD_PER_S", help="gyro drift step [rad/s]")
    ev.add_argument("--accel-g", type=f, metavar="G", help="linear acceleration a/g of an event")
    ev.add_argument("--accel-duration", type=f, metavar="S", help="duration of that event [s]")
    ev.add_argument("--vib-amplitude-g", type=f, metavar="A", help="vibration amplitude [g]")
    ev.add_argument("--vib-frequency", type=f, metavar="HZ", help="vibration frequency [Hz]")
    err = p.add_argument_group("error path (thesis: saturation, then aperiodic unit)")
    err.add_argument("--bias", type=f, metavar="RAD_PER_S",
                     help="largest gyro bias to track: minimum saturation level guidance")
    err.add_argument("--saturation", type=f, metavar="RAD",
                     help="saturation (clip) level [rad] (0 = no clip; default "
                     f"{SHIPPED.saturation_limit_rad:g}, shipped; with it or --bias the "
                     "saturation guidance is printed)")
    err.add_argument("--aperiodic", type=f, metavar="S",
                     help="aperiodic unit time constant T [s] (0 = off; needs T < k1/k2; "
                     f"default {SHIPPED.aperiodic_time_constant_s:g}, shipped)")
    err.add_argument("--initial-error", type=f, metavar="RAD", default=PAPER_INITIAL_ERROR_RAD,
                     help="initial error for the clipped recovery time (default 0.1, Ryzhkov & "
                     "Karpenko's)")
    p.add_argument("--thesis", action="store_true",
                   help="run the thesis requirement check (fixed base 28.8', disturbed 90')")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(run=run)


def _gains(args: argparse.Namespace) -> tuple[float, float, str]:
    """(k1, k2, source) from the arguments, validated; raises CliError (exit 2)."""
    inverse = args.n is not None or args.period is not None
    if inverse and (args.k1 is not None or args.k2 is not None):
        raise CliError("give either --k1/--k2 or --n/--period (with --xi), not both", 2)
    if args.xi is not None and not inverse:
        raise CliError("--xi needs --n or --period (with --k1/--k2, xi = k1/sqrt(k2) follows)", 2)
    if inverse:
        xi = 1.0 if args.xi is None else args.xi
        if xi <= 0.0:
            raise CliError(f"--xi must be > 0 (got {xi:g})", 2)
        if args.n is not None:
            if args.n <= 0.0:
                raise CliError(f"--n must be > 0 rad/s (got {args.n:g})", 2)
            k1, k2 = design.gains_from_natural_frequency(args.n, xi)
            return k1, k2, f"n = {args.n:g} rad/s, xi = {xi:g}"
        if args.period <= 0.0:
            raise CliError(f"--period must be > 0 s (got {args.period:g})", 2)
        k1, k2 = design.gains_from_period(args.period, xi)
        return k1, k2, f"period = {args.period:g} s, xi = {xi:g}"
    k1 = SHIPPED.k1 if args.k1 is None else args.k1
    k2 = SHIPPED.k2 if args.k2 is None else args.k2
    if k1 < 0.0 or k2 < 0.0:
        raise CliError(f"gains must not be negative (k1 = {k1:g} 1/s, k2 = {k2:g} 1/s^2)", 2)
    if k1 == 0.0:
        raise CliError("--k1 0: the loop is undamped (the error oscillates forever); use k1 > 0", 2)
    if k2 == 0.0:
        raise CliError(
            "--k2 0: the natural frequency n = sqrt(k2) is 0, so xi = k1/n, the period 2*pi/n and "
            "the paper's rough omega/n are undefined; use k2 > 0 (k2 = 0 is the first-order "
            "filter, whose drift error is the static omega/k1)", 2)
    given = args.k1 is not None or args.k2 is not None
    return k1, k2, "k1/k2" if given else "shipped parameters"


def _validate(args: argparse.Namespace, k1: float, k2: float) -> None:
    """Pairs and ranges of the disturbance and error-path arguments; raises CliError (exit 2)."""
    if (args.accel_g is None) != (args.accel_duration is None):
        raise CliError("--accel-g and --accel-duration go together (give both or neither)", 2)
    if args.accel_duration is not None and args.accel_duration <= 0.0:
        raise CliError(f"--accel-duration must be > 0 s (got {args.accel_duration:g})", 2)
    if (args.vib_amplitude_g is None) != (args.vib_frequency is None):
        raise CliError("--vib-amplitude-g and --vib-frequency go together (both or neither)", 2)
    if args.vib_frequency is not None and args.vib_frequency <= 0.0:
        raise CliError(f"--vib-frequency must be > 0 Hz (got {args.vib_frequency:g})", 2)
    if args.saturation is not None and args.saturation < 0.0:
        raise CliError(f"--saturation must be >= 0 rad (got {args.saturation:g})", 2)
    t_ap = _aperiodic(args)
    if t_ap < 0.0:
        raise CliError(f"--aperiodic must be >= 0 s (got {t_ap:g})", 2)
    if t_ap > 0.0 and t_ap >= k1 / k2:
        shipped = " (the shipped value; give --aperiodic 0 or a smaller T)" \
            if args.aperiodic is None else ""
        raise CliError(
            f"--aperiodic {t_ap:g} s{shipped} makes the loop unstable: need T < k1/k2 = "
            f"{k1 / k2:.4g} s", 2)


def _aperiodic(args: argparse.Namespace) -> float:
    """The aperiodic time constant [s]: --aperiodic, else the shipped one."""
    return SHIPPED.aperiodic_time_constant_s if args.aperiodic is None else args.aperiodic


def _saturation(args: argparse.Namespace) -> float | None:
    """The clip level [rad] (None = no clip): --saturation (0 = none), else the shipped one."""
    if args.saturation is None:
        return SHIPPED.saturation_limit_rad if SHIPPED.use_saturation else None
    return args.saturation or None


def _angle(prefix: str, rad: float) -> dict[str, float]:
    return {f"{prefix}_rad": rad, f"{prefix}_deg": math.degrees(rad),
            f"{prefix}_arcmin": design.rad_to_arcmin(rad)}


def compute(args: argparse.Namespace) -> dict[str, Any]:
    """All requested results as a JSON-ready dict (validated arguments)."""
    k1, k2, source = _gains(args)
    _validate(args, k1, k2)
    t_ap = _aperiodic(args)
    saturation = _saturation(args)
    hmax, t_hmax = design.impulse_response_peak(k1, k2)
    out: dict[str, Any] = {
        "k1": k1, "k2": k2, "gains_from": source,
        "n": design.natural_frequency(k2),
        "xi": design.seed_damping(k1, k2),
        "zeta": design.classical_damping(k1, k2),
        "period_s": design.natural_period_s(k2),
        "settling_time_s": design.settling_time_s(k1, k2),
        "settling_time_envelope_s": design.envelope_settling_time_s(k1, k2),
        "impulse_peak_s": hmax, "impulse_peak_time_s": t_hmax,
        "aperiodic_time_constant_s": t_ap,
        "saturation_rad": saturation,
    }
    if args.drift is not None:
        peak = design.drift_peak(k1, k2, args.drift, t_ap)
        out["drift_rad_s"] = args.drift
        out.update(_angle("drift_peak_error", peak.magnitude))
        out["drift_peak_time_s"] = peak.time_s
        out.update(_angle("drift_rough_error", design.rough_peak_error_rad(k2, args.drift)))
    if args.accel_g is not None:
        g, tau = args.accel_g, args.accel_duration
        peak = design.accel_event_peak(k1, k2, g, tau, t_ap)
        out["accel_g"], out["accel_duration_s"] = g, tau
        out.update(_angle("accel_peak_error", peak.magnitude))
        out["accel_peak_time_s"] = peak.time_s
        out.update(_angle("accel_short_approx", design.accel_event_short_approx_rad(k1, g, tau)))
        rate = design.seed_equivalent_rate_rad_s(k2, g, tau)
        out.update(_angle("accel_rough_error", design.rough_peak_error_rad(k2, rate)))
        out.update(_angle("accel_no_filter_error", abs(g)))
    if args.vib_amplitude_g is not None:
        a, fr = args.vib_amplitude_g, args.vib_frequency
        out["vibration_amplitude_g"], out["vibration_frequency_hz"] = a, fr
        out.update(_angle("vibration_peak_error",
                          design.vibration_peak_error_rad(k1, k2, a, fr, t_ap)))
        out.update(_angle("vibration_approx", design.vibration_approx_rad(k1, a, fr)))
    if args.bias is not None or args.saturation is not None:
        out["saturation_guidance"] = _guidance(args, k1, k2)
    out["shipped_loop"] = shipped_loop()
    if args.thesis:
        rows = thesis.thesis_check(k1, k2, saturation, t_ap)
        out["thesis"] = {
            "limits_arcmin": dict(thesis.THESIS_LIMITS_ARCMIN),
            "saturation_rad": saturation,
            "aperiodic_time_constant_s": t_ap,
            "checks": [{"name": r.name, "description": r.description,
                        "peak_arcmin": r.peak_arcmin, "limit_arcmin": r.limit_arcmin,
                        "passed": r.passed, "method": r.method} for r in rows],
            "passed": all(r.passed for r in rows),
        }
    return out


def _guidance(args: argparse.Namespace, k1: float, k2: float) -> dict[str, Any]:
    g: dict[str, Any] = {}
    if args.bias is not None:
        g["bias_rad_s"] = args.bias
        g["min_saturation_rad"] = design.min_saturation_limit_rad(k1, k2, args.bias)
    lim = _saturation(args)  # the clip in force: --saturation, else the shipped one
    if args.bias is not None and lim is not None:
        g["saturation_ok_for_bias"] = lim >= g["min_saturation_rad"]
    if lim is not None:
        g["saturation_rad"] = lim
        g["initial_error_rad"] = args.initial_error
        g["recovery_time_k1_s"] = design.clipped_recovery_time_s(k1, lim, args.initial_error)
        g["recovery_time_pi_s"] = design.clipped_recovery_time_s(k1, lim, args.initial_error, k2)
        if args.accel_g is not None:
            err = design.clipped_accel_error_rad(k1, k2, lim, args.accel_g, args.accel_duration)
            g.update(_angle("clipped_accel_error", err))
    return g


def _fmt_angle(rad: float) -> str:
    return f"{math.degrees(rad):10.4g} deg {design.rad_to_arcmin(rad):9.4g}'"


def render(out: dict[str, Any]) -> str:
    """The human-readable table of :func:`compute`'s result."""
    zeta = out["zeta"]
    kind = "oscillating" if zeta < 1.0 else ("critical" if zeta == 1.0 else "overdamped")
    lines = [
        "compensation scheme W(s) = k1 + k2/s (Ryzhkov & Karpenko)"
        + ("" if out["gains_from"] == "k1/k2" else f", gains from {out['gains_from']}"),
        f"  k1                         {out['k1']:.6g} 1/s",
        f"  k2                         {out['k2']:.6g} 1/s^2",
        f"  n = sqrt(k2)               {out['n']:.6g} rad/s",
        f"  xi = k1/n (paper)          {out['xi']:.6g}",
        f"  zeta = k1/(2n)             {zeta:.6g} ({kind})",
        f"  period 2*pi/n              {out['period_s']:.2f} s",
        f"  settling time (2 %)        {out['settling_time_s']:.1f} s exact (initial-error "
        f"response); envelope ln(50)/sigma {out['settling_time_envelope_s']:.1f} s",
        f"  max|h|, h = 1/D impulse    {out['impulse_peak_s']:.4g} s at "
        f"{out['impulse_peak_time_s']:.1f} s (drift peak per rad/s of drift)",
    ]
    if out["aperiodic_time_constant_s"] > 0.0:
        lines.append(f"  aperiodic unit T           {out['aperiodic_time_constant_s']:g} s "
                     "(included in the peak errors below; the rows above are without it)")
    rows = []
    if "drift_rad_s" in out:
        rows.append((f"drift step {out['drift_rad_s']:g} rad/s", out["drift_peak_error_rad"],
                     f"{'omega/n':16}{_fmt_angle(out['drift_rough_error_rad'])}"))
    if "accel_g" in out:
        rows.append((f"accel {out['accel_g']:g} g for {out['accel_duration_s']:g} s",
                     out["accel_peak_error_rad"],
                     f"{'k2*(a/g)*tau/n':16}{_fmt_angle(out['accel_rough_error_rad'])}"))
        rows.append(("  short-event k1*(a/g)*tau", out["accel_short_approx_rad"], ""))
        rows.append(("  without filter (a/g)", out["accel_no_filter_error_rad"], ""))
    if "vibration_frequency_hz" in out:
        rows.append((f"vibration {out['vibration_amplitude_g']:g} g at "
                     f"{out['vibration_frequency_hz']:g} Hz", out["vibration_peak_error_rad"],
                     f"{'A*k1/(2 pi f)':16}{_fmt_angle(out['vibration_approx_rad'])}"))
    if rows:
        lines += ["", f"{'peak errors':29}{'exact':27}paper's rough formula"]
        lines += [f"  {name:27}{_fmt_angle(rad)}   {rough}".rstrip() for name, rad, rough in rows]
    g = out.get("saturation_guidance")
    if g:
        lines += ["", "saturation guidance"]
        if "min_saturation_rad" in g:
            lines.append(f"  min clip 2*bias*max|h|     {g['min_saturation_rad']:.4g} rad "
                         f"(bias {g['bias_rad_s']:g} rad/s)")
        if "saturation_ok_for_bias" in g:
            ok = "OK" if g["saturation_ok_for_bias"] else "TOO LOW: the bias is tracked slowly"
            lines.append(f"  clip {g['saturation_rad']:g} rad                {ok}")
        if "recovery_time_k1_s" in g:
            lines.append(f"  remove {g['initial_error_rad']:g} rad at the clip   "
                         f"{g['recovery_time_k1_s']:.1f} s (k1 only: e0/(k1 L)); "
                         f"{g['recovery_time_pi_s']:.1f} s with the integral (overshoots)")
        if "clipped_accel_error_rad" in g:
            lines.append(f"  clipped accel event        {_fmt_angle(g['clipped_accel_error_rad'])}"
                         "   (k1 L tau + k2 L tau^2/2, upper estimate)")
    th = out.get("thesis")
    if th:
        sat = "none" if th["saturation_rad"] is None else f"{th['saturation_rad']:g} rad"
        lines += ["", f"thesis requirements (Habliuk 2023): saturation {sat}, aperiodic "
                      f"{th['aperiodic_time_constant_s']:g} s"]
        for c in th["checks"]:
            verdict = "PASS" if c["passed"] else "FAIL"
            lines.append(f"  {c['name']:18}{c['peak_arcmin']:9.2f}' <= {c['limit_arcmin']:g}'  "
                         f"{verdict}  {c['description']} [{c['method']}]")
        lines.append(f"  overall: {'PASS' if th['passed'] else 'FAIL'}")
    lines += ["", "where the shipped filter departs from this W(s) (shipped parameters; the "
              "formulas above hold in steady flight, bias learned, small velocity swing)"]
    lines += [f"  {row['when']:33}{row['loop']}" for row in out["shipped_loop"]]
    return "\n".join(lines)


def shipped_loop(p: FilterParams = SHIPPED) -> list[dict[str, str]]:
    """Where the loop that ships is not W(s) = k1 + k2/s with the clip and the thesis's
    aperiodic unit (core/step.py, core/bias.py): each condition and the loop it runs then."""
    k2_raised = p.bias_learning_k2
    k1_raised = max(p.k1, 2.0 * math.sqrt(k2_raised))
    return [
        {"when": "start-up, rest, recovery",
         "loop": f"k1 = startup_k1 = {p.startup_k1:g} 1/s, no clip, no aperiodic unit, no bias "
                 f"learning (start-up: {p.startup_duration_s:g} s; in motion the running mean "
                 "of the accelerometer)"},
        {"when": "bias uncertain (no still phase)",
         "loop": f"k2 raised towards bias_learning_k2 = {k2_raised:g} 1/s^2 and k1 to at least "
                 f"2*sqrt(k2) = {k1_raised:.3g} 1/s (critically damped, n = "
                 f"{math.sqrt(k2_raised):.3g} rad/s), fading as the bias is learned; the "
                 "published attitude may come from the twin without it (two bias hypotheses, "
                 "docs/filter.md)"},
        {"when": "velocity swing sigma_V",
         "loop": "k1 lowered to sqrt(d/sigma_V), d the gyro's drift rate (bias estimate's error "
                 "+ 1 % of the rotation rate), never above k1"},
        {"when": "clip",
         "loop": f"{p.saturation_limit_rad:g} rad only under a linear acceleration with the "
                 f"gyro below rotation_threshold_rad_s = {p.rotation_threshold_rad_s:g} rad/s; "
                 "otherwise none"},
        {"when": "aperiodic unit",
         "loop": f"T = {p.aperiodic_time_constant_s:g} s capped at {LOOP_LAG_FRACTION:g}/k1 "
                 "(running k1) outside the clip; a share aperiodic_prefilter = "
                 f"{p.aperiodic_prefilter:g} of each correction also turns its memory (0: the "
                 "thesis's unit, 1: a pre-filter of the specific force)"},
    ]


def run(args: argparse.Namespace) -> int:
    """Print the design report (table or JSON); exit 0."""
    try:
        out = compute(args)
    except ValueError as exc:  # anything the argument checks above did not anticipate
        raise CliError(str(exc), 2) from None
    if args.json:
        print(json.dumps(out, allow_nan=False))
    else:
        print(render(out))
    return 0
