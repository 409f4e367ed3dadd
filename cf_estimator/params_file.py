"""ROS 2 parameter YAML files: read them without ROS, write them from the schema.

The same file drives the node (``--params-file``), the replay and the tuner. Layout::

    /**:                      # or the node's name, e.g. cf_estimator or /ns/cf_estimator
      ros__parameters:
        k1: 0.5

:func:`all_specs` is the one combined schema (filter + pipeline) that the node declares and the
CLI lists. :func:`render_params_yaml` writes every parameter with a comment (unit, range,
description); floats are always written with a decimal point because ROS 2 refuses an integer
for a double parameter. Run ``python3 -m cf_estimator.params_file > config/cf_estimator.yaml``
to regenerate the shipped file (a test checks it matches).
"""

from __future__ import annotations

import fnmatch
import math
import sys
import textwrap
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from cf_estimator.core.params import FilterParams
from cf_estimator.pipeline.params import PipelineParams
from cf_estimator.schema import ParameterError, ParamSpec, as_dict, specs_of

DEFAULT_NODE_NAME = "cf_estimator"
#: Parameters every ROS 2 node may have; present in a file, they are not "unknown".
ROS_STANDARD_PARAMETERS = ("use_sim_time", "start_type_description_service")
ROS_STANDARD_PREFIXES = ("qos_overrides.",)


def all_specs() -> tuple[ParamSpec, ...]:
    """Every parameter of the package: FilterParams' then PipelineParams', schema order."""
    return specs_of(FilterParams) + specs_of(PipelineParams)


def build_params(values: Mapping[str, Any]) -> tuple[FilterParams, PipelineParams]:
    """Both parameter objects from a flat name → value mapping (defaults for missing names).

    Raises :class:`ParameterError` (one line, naming the parameter) on unknown names or invalid
    values.
    """
    fnames = {s.name for s in specs_of(FilterParams)}
    pnames = {s.name for s in specs_of(PipelineParams)}
    unknown = sorted(set(values) - fnames - pnames)
    if unknown:
        raise ParameterError(f"unknown parameter(s): {', '.join(unknown)}")
    fp = FilterParams(**{k: v for k, v in values.items() if k in fnames})
    pp = PipelineParams(**{k: v for k, v in values.items() if k in pnames})
    return fp, pp


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, Mapping):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = value


def _node_key_matches(key: str, node_name: str | None) -> bool:
    if key in ("/**", "**"):
        return True
    if node_name is None:
        return True
    last = key.rstrip("/").rsplit("/", 1)[-1]
    return fnmatch.fnmatchcase(node_name, last)


def load_params_file(
    path: str | Path, node_name: str | None = None
) -> tuple[FilterParams, PipelineParams, list[str]]:
    """Read a ROS 2 parameter file → ``(FilterParams, PipelineParams, warnings)``.

    Sections are top-level keys holding ``ros__parameters``: ``/**`` always applies; a
    node-name key (``cf_estimator``, ``/ns/cf_estimator``, wildcards allowed) applies when it
    matches ``node_name``, or always when ``node_name`` is None. Later sections override
    earlier ones, as in ROS. Warnings: unknown keys (ignored), sections for other nodes, a file
    with no applicable section (ROS would silently ignore it). Invalid values, and integers
    written for float parameters (ROS 2 rejects them), raise :class:`ParameterError`.
    """
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise ParameterError(f"{path}: cannot read parameter file: {exc}".splitlines()[0]) from None
    warnings: list[str] = []
    if doc is None:
        doc = {}
    if not isinstance(doc, Mapping):
        raise ParameterError(f"{path}: not a ROS 2 parameter file (top level is not a mapping)")
    values: dict[str, Any] = {}
    applied = 0
    for key, section in doc.items():
        key = str(key)
        if not isinstance(section, Mapping) or "ros__parameters" not in section:
            warnings.append(
                f"{path}: top-level key '{key}' has no 'ros__parameters' (ignored; ROS 2 expects "
                f"'/**:' or '<node name>:' then 'ros__parameters:')"
            )
            continue
        if not _node_key_matches(key, node_name):
            warnings.append(f"{path}: section '{key}' is for another node (ignored)")
            continue
        applied += 1
        flat: dict[str, Any] = {}
        _flatten("", section["ros__parameters"] or {}, flat)
        values.update(flat)
    if applied == 0:
        target = f"'{node_name}'" if node_name else "this node"
        warnings.append(
            f"{path}: no section applies to {target} (use '/**:' or the node name): "
            "nothing loaded, defaults in force"
        )
    specs = {s.name: s for s in all_specs()}
    known: dict[str, Any] = {}
    for name, value in values.items():
        if name in specs:
            spec = specs[name]
            if spec.kind == "float" and isinstance(value, int) and not isinstance(value, bool):
                raise ParameterError(
                    f"{path}: {name}: {value} is an integer; write {float(value)!r} (ROS 2 "
                    "rejects an integer for a double parameter)"
                )
            known[name] = value
        elif name in ROS_STANDARD_PARAMETERS or name.startswith(ROS_STANDARD_PREFIXES):
            continue
        else:
            warnings.append(f"{path}: unknown parameter '{name}' (ignored)")
    try:
        fp, pp = build_params(known)
    except ParameterError as exc:
        raise ParameterError(f"{path}: {exc}") from None
    return fp, pp, warnings


def format_value(spec: ParamSpec, value: Any) -> str:
    """A YAML scalar for ``value``: floats always with a '.', strings quoted, bools lower case."""
    if spec.kind == "bool":
        return "true" if value else "false"
    if spec.kind == "int":
        return str(int(value))
    if spec.kind == "float":
        x = float(value)
        if not math.isfinite(x):
            raise ParameterError(f"{spec.name}: cannot write a non-finite value {x!r}")
        text = repr(x)
        mantissa, _, exponent = text.partition("e")
        if "." not in mantissa:
            mantissa += ".0"
        # YAML 1.1 readers (PyYAML) need a '.' and a signed exponent to see a float.
        if exponent and exponent[0] not in "+-":
            exponent = "+" + exponent
        return mantissa + ("e" + exponent if exponent else "")
    return "'" + str(value).replace("'", "''") + "'"


def _comment(spec: ParamSpec) -> list[str]:
    rng = spec.range_text()
    parts = [f"[{spec.unit}]"] if spec.unit else []
    if rng:
        parts.append(f"range {rng}")
    if spec.read_only:
        parts.append("(read-only at run time)")
    text = (" ".join(parts) + ". " if parts else "") + spec.description
    return ["# " + line for line in textwrap.wrap(text, width=94)]


def render_params_yaml(
    filter_params: FilterParams | None = None,
    pipeline_params: PipelineParams | None = None,
    *,
    node_key: str = "/**",
) -> str:
    """The parameter file for these values (defaults when None), every parameter commented."""
    fp = filter_params if filter_params is not None else FilterParams()
    pp = pipeline_params if pipeline_params is not None else PipelineParams()
    values = {**as_dict(fp), **as_dict(pp)}
    lines = [
        "# cf_estimator parameters (ROS 2 parameter file).",
        "# Generated from the parameter schema by cf_estimator.params_file.render_params_yaml;",
        "# every parameter is listed with [unit], range and meaning. '/**' applies to any node",
        "# name, so --params-file is never silently ignored after a rename or a namespace.",
        f"{node_key}:",
        "  ros__parameters:",
    ]
    group = None
    for spec in all_specs():
        if spec.group != group:
            group = spec.group
            lines.append("")
            lines.append(f"    # ---- {group or 'general'} ----")
        lines += ["    " + c for c in _comment(spec)]
        lines.append(f"    {spec.name}: {format_value(spec, values[spec.name])}")
    return "\n".join(lines) + "\n"


def render_params_markdown() -> str:
    """The parameter reference as a Markdown table (name, owner, default, unit, range, meaning)."""
    owners = {s.name: "filter" for s in specs_of(FilterParams)}
    defaults = {**as_dict(FilterParams()), **as_dict(PipelineParams())}
    lines = [
        "| name | owner | default | unit | range | read-only | meaning |",
        "|---|---|---|---|---|---|---|",
    ]
    for spec in all_specs():
        cells = [
            f"`{spec.name}`",
            owners.get(spec.name, "pipeline"),
            f"`{format_value(spec, defaults[spec.name])}`",
            spec.unit or "–",
            spec.range_text() or "–",
            "yes" if spec.read_only else "",
            spec.description.replace("|", "\\|"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    """Print the default parameter file, or with ``--markdown`` the parameter table.

    ``python3 -m cf_estimator.params_file > config/cf_estimator.yaml`` regenerates the shipped
    file; ``--markdown`` prints the table kept in docs/ros_interface.md.
    """
    args = sys.argv[1:] if argv is None else argv
    print(render_params_markdown() if "--markdown" in args else render_params_yaml(), end="")


if __name__ == "__main__":
    main()
