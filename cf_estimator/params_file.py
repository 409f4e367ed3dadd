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

import difflib
import math
import re
import sys
import textwrap
from collections.abc import Iterable, Mapping, Sequence
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


#: Parameters that are gone, with their old default (whose behaviour the filter keeps) and why:
#: a file that still sets one to that value loads (the line is ignored, with a warning), any
#: other value is refused with the reason.
REMOVED_PARAMETERS: dict[str, tuple[Any, str]] = {
    "k3": (0.0, "the double integral of Ryzhkov's full-vector variant is not offered any more "
           "(docs/decisions/0011-full-vector-variant-removed.md)"),
    "mag_mode": ("yaw", "the magnetometer corrects the heading only; the full-vector channel "
                 "is not offered any more (docs/decisions/0011-full-vector-variant-removed.md)"),
    "wide_saturation_limit_rad": (10.0, "outside the clip's condition there is no clip "
                                  "(docs/decisions/0013-fewer-parameters.md)"),
    "acceleration_hold_s": (1.0, "a linear acceleration is held for two stillness blocks, "
                            "2 x rest_window_s (docs/decisions/0013-fewer-parameters.md)"),
    "rest_time_s": (1.0, "two still blocks in a row are rest, 2 x rest_window_s "
                    "(docs/decisions/0013-fewer-parameters.md)"),
    "bias_limit_rad_s": (0.5, "the bias is bounded at 5 x bias_prior_sigma_rad_s "
                         "(docs/decisions/0013-fewer-parameters.md)"),
    "mag_norm_tolerance": (0.2, "mag_field_tolerance sets the norm's and the dip's tolerance "
                           "(docs/decisions/0013-fewer-parameters.md)"),
    "mag_dip_tolerance_rad": (0.17, "mag_field_tolerance sets the norm's and the dip's tolerance "
                              "(docs/decisions/0013-fewer-parameters.md)"),
}


def drop_removed(values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` without the removed parameters set to their old "off" value; a removed
    parameter set to anything else raises :class:`ParameterError` naming it and why."""
    out = dict(values)
    for name, (neutral, why) in REMOVED_PARAMETERS.items():
        if name in out:
            value = out.pop(name)
            if value != neutral:
                raise ParameterError(f"{name}: removed, {why}; only {name}: {neutral!r} "
                                     f"(its old default) is still accepted, got {value!r}")
    return out


def build_params(values: Mapping[str, Any]) -> tuple[FilterParams, PipelineParams]:
    """Both parameter objects from a flat name → value mapping (defaults for missing names).

    Raises :class:`ParameterError` (one line, naming the parameter) on unknown names or invalid
    values; removed parameters at their old default are ignored (:func:`drop_removed`).
    """
    values = drop_removed(values)
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


def fully_qualified_node_name(node_name: str) -> str:
    """``cf_estimator`` → ``/cf_estimator`` (root namespace); ``/ns/name`` stays as it is."""
    name = node_name.strip()
    if not name or name.endswith("/") or "//" in name:
        raise ParameterError(f"not a node name: {node_name!r} (e.g. cf_estimator or /ns/name)")
    return name if name.startswith("/") else "/" + name


def node_key_matches(key: str, node_name: str = DEFAULT_NODE_NAME) -> bool:
    """Whether a parameter file's top-level ``key`` applies to the node ``node_name``.

    ROS 2's rule (rclcpp ``parameter_map_from``, the same for rclpy): a key without a leading
    ``/`` is relative to the root namespace; ``/**`` matches any number of namespace levels and
    ``/*`` exactly one, so ``/**`` applies to every node, ``cf_estimator`` and
    ``/**/cf_estimator`` to ``/cf_estimator``, ``/robot/cf_estimator`` only to that name.
    """
    fqn = fully_qualified_node_name(node_name)
    pattern = key if key.startswith("/") else "/" + key
    regex = ""
    i = 0
    while i < len(pattern):
        if pattern.startswith("/**", i):
            regex += r"(/[^/]+)*"
            i += 3
        elif pattern.startswith("/*", i):
            regex += r"/[^/]+"
            i += 2
        else:
            regex += re.escape(pattern[i])
            i += 1
    return re.fullmatch(regex, fqn) is not None


#: imu_filter_madgwick's parameter names → ours (docs/migrating_from_madgwick.md).
MADGWICK_NAMES: dict[str, str] = {
    "gain": "k1", "zeta": "k2", "declination": "magnetic_declination_rad",
    "yaw_offset": "yaw_offset_rad", "fixed_frame": "tf_parent_frame",
    "orientation_stddev": "orientation_covariance_rad2", "publish_debug_topics": "publish_rpy",
    "remove_gravity_vector": "publish_linear_acceleration",
    "mag_bias_x": "mag_hard_iron_t", "mag_bias_y": "mag_hard_iron_t",
    "mag_bias_z": "mag_hard_iron_t",
}
#: imu_filter_madgwick's hard-iron names, taken as mag_hard_iron_t (x, y, z) [T] when it is not
#: set itself.
MAG_BIAS_ALIASES = ("mag_bias_x", "mag_bias_y", "mag_bias_z")
#: The node name of imu_filter_madgwick's parameter files.
MADGWICK_SECTION = "imu_filter"


def hard_iron_from_aliases(values: Mapping[str, Any]) -> tuple[float, float, float] | None:
    """mag_hard_iron_t from imu_filter_madgwick's ``mag_bias_x/y/z`` (missing ones 0) when any is
    given and ``mag_hard_iron_t`` is not; else None. ParameterError for a non-number."""
    if "mag_hard_iron_t" in values or not any(k in values for k in MAG_BIAS_ALIASES):
        return None
    out = []
    for k in MAG_BIAS_ALIASES:
        v = values.get(k, 0.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ParameterError(f"{k}: expected a number [T], got {v!r}")
        out.append(float(v))
    return (out[0], out[1], out[2])


def suggest_name(name: str) -> str | None:
    """The nearest parameter name to a misspelt ``name`` (None when nothing is close); for an
    imu_filter_madgwick name, ours."""
    known = [s.name for s in all_specs()]
    last = name.rsplit(".", 1)[-1]
    if last in MADGWICK_NAMES:
        return MADGWICK_NAMES[last]
    close = difflib.get_close_matches(last, known, n=1, cutoff=0.6)
    return close[0] if close else None


def unknown_names(names: Iterable[str]) -> list[str]:
    """The parameter names in ``names`` that the node does not declare (sorted).

    ROS's own parameters (``use_sim_time``, ``qos_overrides.*``, ...) are not unknown. The node
    calls this at start-up with the overrides rclpy resolved for it and warns once.
    """
    known = {s.name for s in all_specs()} | set(MAG_BIAS_ALIASES)
    return sorted(
        n for n in set(names)
        if n not in known and n not in ROS_STANDARD_PARAMETERS
        and not n.startswith(ROS_STANDARD_PREFIXES)
    )


def describe_unknown(names: Sequence[str]) -> str:
    """``'k_1' (did you mean 'k1'?), 'foo'``: the unknown names with the nearest valid ones."""
    parts = []
    for n in names:
        near = suggest_name(n)
        if n in REMOVED_PARAMETERS:
            parts.append(f"'{n}' (removed: {REMOVED_PARAMETERS[n][1]})")
        elif n.rsplit(".", 1)[-1] in MADGWICK_NAMES:
            parts.append(f"'{n}' (imu_filter_madgwick's name; ours is '{near}', see "
                         "docs/migrating_from_madgwick.md)")
        else:
            parts.append(f"'{n}'" + (f" (did you mean '{near}'?)" if near else ""))
    return ", ".join(parts)


def _read_doc(path: Path) -> Mapping:
    """The parsed file; ParameterError (one line naming the file, and for bad YAML the line and
    column) when it cannot be read, is not YAML, or is not a mapping of node sections."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        why = getattr(exc, "strerror", None) or str(exc).splitlines()[0]
        raise ParameterError(f"{path}: cannot read the parameter file: {why}") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ParameterError(f"{path}: not valid YAML{where}: {problem}") from None
    if not isinstance(doc, Mapping):
        raise ParameterError(f"{path}: not a ROS 2 parameter file (expected '/**:' or "
                             "'<node name>:' then 'ros__parameters:')")
    return doc


def check_params_file(path: str | Path) -> str | None:
    """None if ``path`` is a readable YAML mapping (what rcl can load), else the problem (one
    line naming the file)."""
    try:
        _read_doc(Path(path))
    except ParameterError as exc:
        return str(exc)
    return None


def params_files(args: Sequence[str]) -> list[str]:
    """The ``--params-file`` paths among ROS arguments (after ``--ros-args``, up to ``--``)."""
    files: list[str] = []
    in_ros = False
    it = iter(args)
    for arg in it:
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--":
            in_ros = False
        elif in_ros and arg == "--params-file":
            path = next(it, None)
            if path is not None:
                files.append(path)
        elif in_ros and arg.startswith("--params-file="):
            files.append(arg.partition("=")[2])
    return files


def _applicable_values(
    path: Path, doc: Mapping, node_name: str
) -> tuple[dict[str, Any], list[str]]:
    """(flat name → value of every section that applies, warnings about the others)."""
    values: dict[str, Any] = {}
    warnings: list[str] = []
    flat_keys = [str(k) for k, v in doc.items()
                 if not (isinstance(v, Mapping) and "ros__parameters" in v)]
    if flat_keys:
        raise ParameterError(
            f"{path}: top-level key '{flat_keys[0]}' has no 'ros__parameters': not a ROS 2 "
            "parameter file (write '/**:' or '<node name>:', then 'ros__parameters:', then the "
            "parameters)"
        )
    applied = 0
    ignored = []
    for key, section in doc.items():
        key = str(key)
        if not node_key_matches(key, node_name):
            ignored.append(key)
            warnings.append(
                f"{path}: section '{key}' is not for node "
                f"'{fully_qualified_node_name(node_name)}' (ignored, as the node ignores it)"
            )
            continue
        applied += 1
        _flatten("", section["ros__parameters"] or {}, values)
    if applied == 0:
        raise ParameterError(
            f"{path}: no section applies to node '{fully_qualified_node_name(node_name)}' "
            f"(sections: {', '.join(ignored)}); use '/**:' or the node name, or --node-name"
            + _madgwick_section_hint(ignored)
        )
    return values, warnings


def _madgwick_section_hint(keys: Sequence[str]) -> str:
    """A hint for imu_filter_madgwick's section name among ``keys`` (empty otherwise)."""
    if any(k.strip("/").rsplit("/", 1)[-1] == MADGWICK_SECTION for k in keys):
        return (f" ('{MADGWICK_SECTION}' is imu_filter_madgwick's node: rename the section and "
                "its parameters as docs/migrating_from_madgwick.md says, e.g. gain -> k1)")
    return ""


def unapplied_file_warning(path: str | Path, node_name: str) -> str | None:
    """One line when no section of the parameter file ``path`` applies to the node
    ``node_name`` (fully qualified), so rclpy silently runs it with the defaults; else None.

    Unreadable or non-parameter files are the start-up checks' business: None here.
    """
    path = Path(path)
    try:
        doc = _read_doc(path)
        keys = [str(k) for k in doc]
        if any(node_key_matches(k, node_name) for k in keys):
            return None
    except ParameterError:
        return None
    fqn = fully_qualified_node_name(node_name)
    short = fqn.rsplit("/", 1)[-1]
    hint = _madgwick_section_hint(keys)
    if any(k.lstrip("/").rsplit("/", 1)[-1].endswith("_node") for k in keys):
        hint = (f" ('{keys[0]}' looks like the executable's name; the node is named "
                f"'{short}')")
    return (f"parameter file {path}: none of its sections ({', '.join(keys)}) is for this node "
            f"'{fqn}'{hint}: NONE of its parameters are in force, the node runs with the "
            f"defaults; name the section '/**:' or '{short}:'")


def unknown_keys(path: str | Path, node_name: str = DEFAULT_NODE_NAME) -> list[str]:
    """The parameter names in the sections of ``path`` that apply to ``node_name`` and that
    the node does not know (sorted); ParameterError when the file is not a parameter file."""
    path = Path(path)
    values, _ = _applicable_values(path, _read_doc(path), node_name)
    return unknown_names(values)


def check_names(path: str | Path, node_name: str = DEFAULT_NODE_NAME
                ) -> tuple[dict[str, Any], list[str]]:
    """The names a parameter file gives the node ``node_name``: ``(flat name → value of the
    sections that apply, warnings about the others)``.

    Raises :class:`ParameterError` with the one line that ``replay --params`` and the node with
    ``strict_parameters`` both give: not a parameter file, no section for this node (e.g. an
    imu_filter_madgwick file's ``imu_filter:``), unknown or misspelt names (the nearest valid
    name suggested).
    """
    path = Path(path)
    values, warnings = _applicable_values(path, _read_doc(path), node_name)
    removed = [n for n in REMOVED_PARAMETERS if n in values]
    try:
        values = drop_removed(values)
    except ParameterError as exc:
        raise ParameterError(f"{path}: {exc}") from None
    warnings = [*warnings, *(f"{path}: {n}: removed, the line is ignored "
                             f"({REMOVED_PARAMETERS[n][1]})" for n in removed)]
    unknown = unknown_names(values)
    if unknown:
        raise ParameterError(f"{path}: unknown parameter {describe_unknown(unknown)}")
    return values, warnings


def load_params_file(
    path: str | Path, node_name: str = DEFAULT_NODE_NAME
) -> tuple[FilterParams, PipelineParams, list[str]]:
    """Read a ROS 2 parameter file as the node ``node_name`` would → ``(FilterParams,
    PipelineParams, warnings)``.

    Sections are top-level keys holding ``ros__parameters``; those matching the node name
    (:func:`node_key_matches`: ``/**``, the name, wildcards) apply, later ones overriding
    earlier ones as in ROS; the others are ignored with a warning. Refused with
    :class:`ParameterError` (one line): a file that is not a parameter file (no
    ``ros__parameters`` under a top-level key, empty), a file with no section for this node,
    unknown parameter names (the nearest valid name suggested), invalid values, and integers
    written for float parameters (ROS 2 rejects them).
    """
    path = Path(path)
    values, warnings = check_names(path, node_name)
    try:
        alias = hard_iron_from_aliases(values)
    except ParameterError as exc:
        raise ParameterError(f"{path}: {exc}") from None
    if alias is not None:
        values = {k: v for k, v in values.items() if k not in MAG_BIAS_ALIASES}
        values["mag_hard_iron_t"] = list(alias)
        warnings = [*warnings, f"{path}: imu_filter_madgwick's mag_bias_x/y/z taken as "
                    f"mag_hard_iron_t {list(alias)} [T] (write mag_hard_iron_t)"]
    else:
        values = {k: v for k, v in values.items() if k not in MAG_BIAS_ALIASES}
    specs = {s.name: s for s in all_specs()}
    known: dict[str, Any] = {}
    for name, value in values.items():
        spec = specs.get(name)
        if spec is None:
            continue  # a ROS standard parameter
        if spec.kind == "float" and isinstance(value, int) and not isinstance(value, bool):
            raise ParameterError(
                f"{path}: {name}: {value} is an integer; write {float(value)!r} (ROS 2 "
                "rejects an integer for a double parameter)"
            )
        if (spec.kind == "float_list" and isinstance(value, list) and value
                and all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
            raise ParameterError(
                f"{path}: {name}: {value} is a list of integers; write "
                f"{[float(v) for v in value]} (ROS 2 rejects integers for a double array)"
            )
        known[name] = value
    try:
        fp, pp = build_params(known)
    except ParameterError as exc:
        raise ParameterError(f"{path}: {exc}") from None
    return fp, pp, warnings


def explicit_names(path: str | Path | None, node_name: str = DEFAULT_NODE_NAME) -> frozenset[str]:
    """The parameter names the file ``path`` sets for ``node_name`` (empty without a file):
    PX4 input applies its conventions to the others only (``cf_estimator.pipeline.px4``)."""
    if path is None:
        return frozenset()
    path = Path(path)
    values, _ = _applicable_values(path, _read_doc(path), node_name)
    return frozenset(values)


def format_value(spec: ParamSpec, value: Any) -> str:
    """A YAML scalar for ``value``: floats always with a '.', strings quoted, bools lower case."""
    if spec.kind == "bool":
        return "true" if value else "false"
    if spec.kind == "int":
        return str(int(value))
    if spec.kind == "float_list":
        return "[" + ", ".join(format_value(_FLOAT, v) for v in value) + "]"
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


_FLOAT = ParamSpec(name="element", kind="float", default=0.0, unit="", description="")


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
    only: Sequence[str] | None = None,
    notes: Mapping[str, str] | None = None,
) -> str:
    """The parameter file for these values (defaults when None), every parameter commented.

    ``only``: write just these parameters (e.g. the ones a tuner changed: a file that resets
    nothing else when it follows another ``--params-file``); ``notes``: name → one more comment
    line above that parameter (e.g. "ended on its search bound").
    """
    fp = filter_params if filter_params is not None else FilterParams()
    pp = pipeline_params if pipeline_params is not None else PipelineParams()
    values = {**as_dict(fp), **as_dict(pp)}
    notes = notes or {}
    lines = [
        "# cf_estimator parameters (ROS 2 parameter file).",
        "# Generated from the parameter schema by cf_estimator.params_file.render_params_yaml;",
        ("# every parameter is listed with [unit], range and meaning." if only is None else
         "# only the parameters named below, each with [unit], range and meaning; the node's"
         "\n# defaults (or an earlier --params-file) hold for every other one.")
        + " '/**' applies to any node",
        "# name, so --params-file is never silently ignored after a rename or a namespace.",
        f"{node_key}:",
        "  ros__parameters:",
    ]
    group = None
    for spec in all_specs():
        if only is not None and spec.name not in only:
            continue
        if spec.group != group:
            group = spec.group
            lines.append("")
            lines.append(f"    # ---- {group or 'general'} ----")
        lines += ["    " + c for c in _comment(spec)]
        if spec.name in notes:
            lines += ["    # NOTE: " + line for line in textwrap.wrap(notes[spec.name], 86)]
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
