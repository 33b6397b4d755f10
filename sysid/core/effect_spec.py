"""Parsing of effect specifications such as ``delay:23`` or ``resonance:f0_hz=3400,q=8``.

One syntax serves ``simulate --effect`` (an effect hidden in a synthetic session)
and ``refine --add`` (a structure added to a model): ``KIND`` alone (all defaults),
``KIND:V1,V2`` (values in the kind's parameter order) or ``KIND:NAME=V,...``.
A list value separates its items with ``/`` (``periodic-disturbance:frequencies_hz=50/100``).
Each user has its own parameter table (``ParameterSpec`` per kind); the parser checks
names, types and ranges and names the offending part in a one-line error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import HelmetAncError

__all__ = ["ParameterSpec", "EffectSpec", "parse_effect"]


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter of an effect: name (with unit suffix), default, inclusive range, kind."""

    name: str
    default: float | int | tuple | None
    low: float = -math.inf
    high: float = math.inf
    kind: str = "float"  # "float", "int" or "list" (of floats)


@dataclass(frozen=True)
class EffectSpec:
    """A parsed effect: its kind and a complete parameter dict (defaults filled in)."""

    kind: str
    params: dict

    def to_dict(self) -> dict:
        return {"effect": self.kind, "params": dict(self.params)}


def _number(text: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise HelmetAncError(f"{where}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise HelmetAncError(f"{where}: {text!r} is not a finite number")
    return value


def _convert(spec: ParameterSpec, text: str, where: str):
    if spec.kind == "list":
        items = [item for item in text.split("/") if item.strip()]
        if not items:
            raise HelmetAncError(f"{where}: {spec.name} needs at least one value")
        values = tuple(_number(item, where) for item in items)
    else:
        value = _number(text, where)
        if spec.kind == "int":
            if value != int(value):
                raise HelmetAncError(f"{where}: {spec.name} must be a whole number; found {text}")
            value = int(value)
        values = (value,)
    for value in values:
        if not spec.low <= value <= spec.high:
            raise HelmetAncError(f"{where}: {spec.name} must be between {spec.low:g} and {spec.high:g}; found {value:g}")
    return values if spec.kind == "list" else values[0]


def parse_effect(text: str, table: dict[str, tuple[ParameterSpec, ...]], option: str = "--effect") -> EffectSpec:
    """Parse ``KIND[:PARAMS]`` against ``table`` (kind -> its parameters in order)."""
    kind, _, rest = str(text).strip().partition(":")
    kind = kind.strip().lower()
    if kind not in table:
        raise HelmetAncError(f"{option} {text!r}: unknown effect {kind!r}; expected one of {', '.join(table)}")
    specs = table[kind]
    where = f"{option} {text!r}"
    params = {}
    parts = [part.strip() for part in rest.split(",")] if rest.strip() else []
    for position, part in enumerate(parts):
        if not part:
            raise HelmetAncError(f"{where}: empty parameter")
        if "=" in part:
            name, _, value = part.partition("=")
            name = name.strip().replace("-", "_")
            spec = next((s for s in specs if s.name == name), None)
            if spec is None:
                names = ", ".join(s.name for s in specs) or "none"
                raise HelmetAncError(f"{where}: unknown parameter {name!r}; {kind} takes {names}")
        else:
            if position >= len(specs):
                raise HelmetAncError(f"{where}: {kind} takes at most {len(specs)} parameter(s); found {len(parts)}")
            spec, value = specs[position], part
        if spec.name in params:
            raise HelmetAncError(f"{where}: {spec.name} given twice")
        params[spec.name] = _convert(spec, value.strip(), where)
    for spec in specs:
        params.setdefault(spec.name, spec.default)
    return EffectSpec(kind, params)
