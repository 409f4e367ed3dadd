"""``bench ablate``: each mechanism off, paired per recording against the base, family by family."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from cf_estimator.cli.base import CliError
from cf_estimator.cli.bench_cmd.common import check_outputs, csv_list, families_option, write_json
from cf_estimator.cli.common import add_jobs_option, load_params, note

#: The ablation rows of the shipped mechanisms that have a parameter: name → overrides that
#: switch the mechanism off (or to its neutral value).
BUILTIN_VARIANTS: dict[str, tuple[str, ...]] = {
    "no-clip": ("use_saturation=false",),
    "no-in-flight-learning": ("bias_learning_k2=0",),
    "no-rest-learning": ("rest_bias_learning=false",),
    "no-recovery": ("recovery_trigger_s=0",),
    "prefilter-0": ("aperiodic_prefilter=0",),
    "prefilter-1": ("aperiodic_prefilter=1",),
    "no-aperiodic-unit": ("aperiodic_time_constant_s=0",),
    "no-mag-rejection": ("mag_rejection=false",),
    "no-startup-phase": ("startup_duration_s=0",),
}


def add_parser(sub: Any) -> None:
    """Add ``bench ablate`` to the ``bench`` sub-parsers."""
    ab = sub.add_parser(
        "ablate", help="each mechanism off against the base: paired per-recording deltas per "
        "family, and the leave-one-family-out verdict",
        description=(
            "Scores every dev recording with our filter online (the base: --params or the "
            "shipped defaults) and with each variant, and compares them recording by recording "
            "per family: mean delta (variant - base; positive = worse), its paired standard "
            "error, better/worse counts and a sign test. Leave one family out: a variant "
            "chosen on the other families must not lose on the held-out one beyond 2 paired "
            "standard errors. Variants: --variant NAME:PARAM=VALUE[,PARAM=VALUE...] (repeat), "
            f"or --builtin for the shipped mechanisms ({', '.join(BUILTIN_VARIANTS)})."
        ),
    )
    ab.add_argument("--data", default="../shared/data", metavar="DIR",
                    help="directory holding euroc/, phantom4/, phantom4_horizontal/, broad/ "
                    "(default %(default)s)")
    ab.add_argument("--families", default=",".join(_families()), metavar="LIST",
                    help="comma-separated subset of %(default)s")
    ab.add_argument("--params", metavar="YAML", help="the base: a ROS 2 parameter file "
                    "(default: the shipped defaults)")
    ab.add_argument("--variant", action="append", default=[], metavar="NAME:P=V[,P=V]",
                    help="a variant: the base with these filter parameters changed (none after "
                    "the colon: this checkout's filter as it is, against --base-scores made by "
                    "another version)")
    ab.add_argument("--builtin", action="store_true",
                    help="add the built-in ablation rows of the shipped mechanisms")
    ab.add_argument("--base-scores", metavar="JSON", help="reuse the base's scores from an "
                    "earlier --json output (same data and base)")
    ab.add_argument("--json", metavar="OUT", help="write every score and comparison as JSON")
    ab.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    add_jobs_option(ab)
    ab.set_defaults(run=run)


def _families() -> tuple[str, ...]:
    from cf_estimator.bench.ablation import FAMILIES

    return FAMILIES


def _variants(args: Any) -> dict[str, tuple[str, ...]]:
    out = dict(BUILTIN_VARIANTS) if args.builtin else {}
    for text in args.variant:
        name, sep, rest = text.partition(":")
        if not sep or not name:
            raise CliError(f"--variant: expected NAME:PARAM=VALUE[,...], got {text!r}", 2)
        out[name] = tuple(csv_list(rest))
    if not out:
        raise CliError("bench ablate: no variant (give --variant or --builtin)", 2)
    return out


def run(args: Any) -> int:
    """``bench ablate``."""
    from cf_estimator.bench import ablation
    from cf_estimator.core.params import ParameterError

    check_outputs(args, "json")
    families = families_option(args, ablation.FAMILIES)
    if not Path(args.data).is_dir():
        raise CliError(f"--data: {args.data} is not a directory", 2)
    base_params, _ = load_params(args.params)
    variants = {}
    for name, overrides in _variants(args).items():
        try:
            changes = dict(ablation.parse_override(o) for o in overrides)
            variants[name] = (overrides, dataclasses.replace(base_params, **changes))
        except (ValueError, ParameterError) as exc:
            raise CliError(f"--variant {name}: {exc}", 2) from None
    if args.base_scores:
        try:
            base = json.loads(Path(args.base_scores).read_text())["base"]
        except (OSError, ValueError, KeyError) as exc:
            raise CliError(f"--base-scores: {args.base_scores}: not an ablate --json output "
                           f"({exc})", 2) from None
    else:
        note("bench ablate: base ...")
        base = ablation.score_all(args.data, base_params, families, args.jobs)
    out: dict[str, Any] = {"base": base, "variants": {}}
    print(f"Ablation against {args.params or 'the shipped defaults'} ({args.data}); delta = "
          "variant - base, positive = worse; paired over the recordings")
    for name, (overrides, params) in variants.items():
        note(f"bench ablate: {name} ...")
        scores = ablation.score_all(args.data, params, families, args.jobs)
        rows = ablation.compare(base, scores)
        print()
        print(ablation.format_comparison(f"{name} ({', '.join(overrides) or 'as is'})", rows,
                                         ablation.unit_of))
        choice, losers = ablation.verdict(rows)
        out["variants"][name] = {
            "overrides": list(overrides), "scores": scores, "verdict": choice, "losers": losers,
            "families": [dataclasses.asdict(r) for r in rows]}
    if args.json:
        write_json(args.json, out)
    return 0
