"""Parameter schema: one declaration per parameter drives validation, ROS, YAML and the CLI.

A parameter is a dataclass field created with :func:`param`. Its metadata (unit, description,
range, choices, read-only flag) is the schema; :func:`specs_of` reads it back, :func:`validate`
checks an instance against it, and the node, the YAML writer and the CLI all iterate over
:func:`specs_of` instead of keeping their own lists.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

T = TypeVar("T")


class ParameterError(ValueError):
    """An invalid parameter value or an unknown parameter name (the message names the parameter)."""


@dataclass(frozen=True)
class ParamSpec:
    """Schema entry of one parameter.

    ``kind`` is one of ``"float"``, ``"int"``, ``"bool"``, ``"str"``, ``"float_list"`` (a fixed
    ``length`` of floats, a ROS double array; a tuple in Python). ``minimum``/``maximum``
    bound numbers (inclusive unless ``*_exclusive``); ``choices`` restricts strings.
    ``read_only`` marks structural parameters that the node refuses to change at run time.
    """

    name: str
    kind: str
    default: Any
    unit: str
    description: str
    minimum: float | None = None
    maximum: float | None = None
    minimum_exclusive: bool = False
    maximum_exclusive: bool = False
    choices: tuple[str, ...] | None = None
    read_only: bool = False
    group: str = ""
    length: int | None = None

    def range_text(self) -> str:
        """Human-readable range, e.g. ``(0, 10]`` or ``{enu, ned}``; empty when unbounded."""
        if self.choices:
            return "{" + ", ".join(self.choices) + "}"
        if self.minimum is None and self.maximum is None:
            return ""
        lo = "-inf" if self.minimum is None else f"{self.minimum:g}"
        hi = "inf" if self.maximum is None else f"{self.maximum:g}"
        left = "(" if self.minimum_exclusive or self.minimum is None else "["
        right = ")" if self.maximum_exclusive or self.maximum is None else "]"
        return f"{left}{lo}, {hi}{right}"

    def check(self, value: Any) -> Any:
        """Return ``value`` converted to this parameter's type, or raise :class:`ParameterError`."""
        value = coerce(self, value)
        if self.kind == "float_list":
            if not all(math.isfinite(v) for v in value):
                raise ParameterError(f"{self.name}: every element must be finite, got {value!r}")
            return value
        if self.kind in ("float", "int"):
            if not math.isfinite(value):
                raise ParameterError(f"{self.name}: must be finite, got {value!r}")
            if self.minimum is not None and (
                value < self.minimum or (self.minimum_exclusive and value == self.minimum)
            ):
                raise ParameterError(f"{self.name}: {value!r} is outside {self.range_text()}")
            if self.maximum is not None and (
                value > self.maximum or (self.maximum_exclusive and value == self.maximum)
            ):
                raise ParameterError(f"{self.name}: {value!r} is outside {self.range_text()}")
        if self.choices is not None and value not in self.choices:
            raise ParameterError(f"{self.name}: {value!r} is not one of {self.range_text()}")
        return value


def coerce(spec: ParamSpec, value: Any) -> Any:
    """Convert ``value`` to the spec's kind, never loosely (no float→bool, no str→float)."""
    kind = spec.kind
    if kind == "bool":
        if isinstance(value, bool):
            return value
        raise ParameterError(f"{spec.name}: expected true/false, got {value!r}")
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParameterError(f"{spec.name}: expected an integer, got {value!r}")
        return int(value)
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{spec.name}: expected a number, got {value!r}")
        return float(value)
    if kind == "float_list":
        if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__iter__"):
            raise ParameterError(f"{spec.name}: expected a list of {spec.length} numbers, "
                                 f"got {value!r}")
        items = list(value)
        number = (int, float, _np_number())
        if len(items) != spec.length or any(
                isinstance(v, bool) or not isinstance(v, number) for v in items):
            raise ParameterError(f"{spec.name}: expected a list of {spec.length} numbers, "
                                 f"got {value!r}")
        return tuple(float(v) for v in items)
    if kind == "str":
        if not isinstance(value, str):
            raise ParameterError(f"{spec.name}: expected a string, got {value!r}")
        return value.lower() if spec.choices else value
    raise ParameterError(f"{spec.name}: unknown kind {kind!r}")  # pragma: no cover - schema bug


def _np_number() -> type:
    """NumPy's scalar base class when NumPy is there (the node runs without it), else float."""
    try:
        import numpy as np
    except ImportError:  # pragma: no cover - NumPy is a dependency of the offline tools
        return float
    return np.number


def param(
    default: Any,
    unit: str,
    description: str,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    minimum_exclusive: bool = False,
    maximum_exclusive: bool = False,
    choices: tuple[str, ...] | None = None,
    read_only: bool = False,
    group: str = "",
) -> Any:
    """Declare a dataclass field that is also a schema entry (see :class:`ParamSpec`)."""
    kind = {bool: "bool", int: "int", float: "float", str: "str", tuple: "float_list"}[
        type(default)]
    meta = dict(
        kind=kind,
        length=len(default) if kind == "float_list" else None,
        unit=unit,
        description=description,
        minimum=minimum,
        maximum=maximum,
        minimum_exclusive=minimum_exclusive,
        maximum_exclusive=maximum_exclusive,
        choices=choices,
        read_only=read_only,
        group=group,
    )
    return dataclasses.field(default=default, metadata={"cf_param": meta})


def specs_of(cls_or_instance: Any) -> tuple[ParamSpec, ...]:
    """The schema entries of a parameter dataclass, in declaration order."""
    cls = cls_or_instance if isinstance(cls_or_instance, type) else type(cls_or_instance)
    return _specs_of_class(cls)


@functools.cache
def _specs_of_class(cls: type) -> tuple[ParamSpec, ...]:
    """specs_of() of a class, built once (ParamSpec is frozen: the tuple is shared safely)."""
    out = []
    for f in dataclasses.fields(cls):
        meta = f.metadata.get("cf_param")
        if meta is None:
            continue
        out.append(ParamSpec(name=f.name, default=f.default, **meta))
    return tuple(out)


@functools.cache
def _names_of_class(cls: type) -> frozenset[str]:
    return frozenset(s.name for s in _specs_of_class(cls))


def validate_fields(instance: Any) -> None:
    """Check and normalise every field of a parameter dataclass in place (frozen-safe)."""
    for spec in specs_of(instance):
        value = spec.check(getattr(instance, spec.name))
        object.__setattr__(instance, spec.name, value)


def from_mapping(cls: type[T], values: Mapping[str, Any], *, strict: bool = True) -> T:
    """Build ``cls`` from a name→value mapping; unknown names raise when ``strict``."""
    names = {s.name for s in specs_of(cls)}
    unknown = sorted(set(values) - names)
    if unknown and strict:
        raise ParameterError(f"unknown parameter(s): {', '.join(unknown)}")
    return cls(**{k: v for k, v in values.items() if k in names})


def replace(instance: T, changes: Mapping[str, Any]) -> T:
    """A validated copy of ``instance`` with ``changes`` applied (unknown names raise)."""
    names = {s.name for s in specs_of(instance)}
    unknown = sorted(set(changes) - names)
    if unknown:
        raise ParameterError(f"unknown parameter(s): {', '.join(unknown)}")
    return dataclasses.replace(instance, **dict(changes))  # type: ignore[type-var]


def as_dict(instance: Any) -> dict[str, Any]:
    """The parameter values of an instance, name → value, in schema order."""
    return {s.name: getattr(instance, s.name) for s in specs_of(instance)}


def split_by_owner(values: Mapping[str, Any], owners: Iterable[type]) -> list[dict[str, Any]]:
    """Split a flat name→value mapping into one dict per parameter class (unknown names raise)."""
    owners = list(owners)
    out: list[dict[str, Any]] = [{} for _ in owners]
    for key, value in values.items():
        for i, cls in enumerate(owners):
            if key in _names_of_class(cls):
                out[i][key] = value
                break
        else:
            raise ParameterError(f"unknown parameter: {key}")
    return out
