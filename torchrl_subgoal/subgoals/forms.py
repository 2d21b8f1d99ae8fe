"""A predicate's file form: reading ``{cell: [4, 9]}`` and the other fields of a subgoal file, with errors
that name the file, the pattern and the field."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from torchrl_subgoal.subgoals.errors import SubgoalFileError
from torchrl_subgoal.subgoals.predicates import Box, Cell, Circle, Condition, Predicate, State


def _unique(mapping: Any, where: str, what: str) -> None:
    """Refuse a parsed mapping that held a key twice (YAML and JSON both keep the last one)."""
    duplicates = getattr(mapping, "duplicates", None)
    if duplicates:
        key, line = duplicates[0]
        at = f" (line {line})" if line else ""
        raise SubgoalFileError(f"{where}: duplicate {what} {key!r}{at}; each must appear once")


def _number(value: Any, where: str, *, integer: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SubgoalFileError(f"{where}: expected a number, got {value!r}")
    if integer and not isinstance(value, int):
        raise SubgoalFileError(f"{where}: expected an integer, got {value!r}")
    if math.isnan(value) or math.isinf(value):
        raise SubgoalFileError(f"{where}: expected a finite number, got {value!r}")
    return value


def _numbers(value: Any, where: str, *, integer: bool = False) -> list[Any]:
    if not isinstance(value, list | tuple) or not value:
        raise SubgoalFileError(f"{where}: expected a non-empty list of numbers, got {value!r}")
    return [_number(v, f"{where}[{i}]", integer=integer) for i, v in enumerate(value)]


def _dims(value: Any, where: str, n: int) -> tuple[int, ...]:
    dims = tuple(int(d) for d in _numbers(value, where, integer=True))
    if len(dims) != n:
        raise SubgoalFileError(f"{where}: has {len(dims)} entries but the centre has {n}")
    if min(dims) < 0 or len(set(dims)) != len(dims):
        raise SubgoalFileError(f"{where}: entries must be distinct non-negative indices, got {list(dims)}")
    return dims


def _description(body: Mapping[str, Any], where: str) -> str | None:
    """A pattern's or file's optional ``description``: text, kept when the file is saved again."""
    value = body.get("description")
    if value is not None and not isinstance(value, str):
        raise SubgoalFileError(f"{where}: expected text, got {value!r}")
    return value


def _check_keys(body: Mapping[str, Any], allowed: set[str], where: str) -> None:
    unknown = set(body) - allowed
    if unknown:
        raise SubgoalFileError(f"{where}: unknown field(s) {sorted(unknown)}; allowed: {sorted(allowed)}")


def parse_predicate(spec: Any, where: str) -> Predicate:
    """Build a predicate from its file form; ``where`` prefixes error messages.

    Examples:
        >>> parse_predicate({"cell": [4, 9]}, "alice.yaml: subgoals[0]").to_dict()
        {'cell': [4, 9]}
        >>> parse_predicate({"cell": [4]}, "alice.yaml: subgoals[0]")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.subgoals.errors.SubgoalFileError: alice.yaml: subgoals[0].cell: expected [row, col], got [4]
    """
    if not isinstance(spec, Mapping):
        raise SubgoalFileError(f"{where}: expected a mapping such as {{cell: [4, 9]}}, got {spec!r}")
    _unique(spec, where, "field")
    kinds = [k for k in ("state", "cell", "circle", "box", "call") if k in spec]
    if len(kinds) != 1:
        raise SubgoalFileError(
            f"{where}: give exactly one predicate among state, cell, circle, box, call; got fields {sorted(spec)}"
        )
    kind = kinds[0]
    if kind == "call":
        _check_keys(spec, {"call", "args"}, where)
        return Condition.from_path(spec["call"], spec.get("args"), where=f"{where}.call")
    if kind == "state":
        _check_keys(spec, {"state"}, where)
        return State(int(_number(spec["state"], f"{where}.state", integer=True)))
    if kind == "cell":
        _check_keys(spec, {"cell", "dims"}, where)
        rc = _numbers(spec["cell"], f"{where}.cell", integer=True)
        if len(rc) != 2:
            raise SubgoalFileError(f"{where}.cell: expected [row, col], got {spec['cell']!r}")
        dims = _dims(spec.get("dims", [0, 1]), f"{where}.dims", 2)
        return Cell(int(rc[0]), int(rc[1]), (dims[0], dims[1]))
    body = spec[kind]
    if len(spec) != 1:
        raise SubgoalFileError(f"{where}: unknown field(s) {sorted(set(spec) - {kind})}")
    if not isinstance(body, Mapping):
        raise SubgoalFileError(f"{where}.{kind}: expected a mapping, got {body!r}")
    _unique(body, f"{where}.{kind}", "field")
    body = dict(body)
    if "center" in body and "centre" not in body:
        body["centre"] = body.pop("center")
    if "centre" not in body:
        raise SubgoalFileError(f"{where}.{kind}.centre: missing")
    centre = tuple(float(c) for c in _numbers(body["centre"], f"{where}.{kind}.centre"))
    if kind == "circle":
        _check_keys(body, {"centre", "radius", "dims"}, f"{where}.circle")
        if "radius" not in body:
            raise SubgoalFileError(f"{where}.circle.radius: missing")
        radius = float(_number(body["radius"], f"{where}.circle.radius"))
        if radius <= 0:
            raise SubgoalFileError(f"{where}.circle.radius: must be positive, got {radius}")
        cdims = _dims(body["dims"], f"{where}.circle.dims", len(centre)) if "dims" in body else None
        return Circle(centre, radius, cdims)
    _check_keys(body, {"centre", "margin", "dims", "slice"}, f"{where}.box")
    if "dims" in body and "slice" in body:
        raise SubgoalFileError(f"{where}.box: give 'dims' or 'slice', not both")
    if "slice" in body:
        bounds = _numbers(body["slice"], f"{where}.box.slice", integer=True)
        if len(bounds) != 2 or bounds[0] < 0 or bounds[1] - bounds[0] != len(centre):
            raise SubgoalFileError(
                f"{where}.box.slice: expected [start, stop) covering {len(centre)} entries, got {bounds}"
            )
        bdims = tuple(range(int(bounds[0]), int(bounds[1])))
    else:
        bdims = _dims(body.get("dims", list(range(len(centre)))), f"{where}.box.dims", len(centre))
    if "margin" not in body:
        raise SubgoalFileError(f"{where}.box.margin: missing")
    raw = body["margin"]
    margins = (
        [float(_number(raw, f"{where}.box.margin"))] * len(centre)
        if not isinstance(raw, list | tuple)
        else [float(m) for m in _numbers(raw, f"{where}.box.margin")]
    )
    if len(margins) != len(centre):
        raise SubgoalFileError(f"{where}.box.margin: has {len(margins)} entries but the centre has {len(centre)}")
    if min(margins) < 0:
        raise SubgoalFileError(f"{where}.box.margin: must be non-negative, got {margins}")
    return Box(centre, tuple(margins), bdims)
