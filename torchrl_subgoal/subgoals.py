"""Subgoal series: ordered subgoals, their achievement predicates and the file format.

A *subgoal series* is what a person who knows the task writes down: a few
subgoals and the order in which they should be achieved. The order is total
(a chain, ``sg_0 ≺ sg_1 ≺ …``) or partial (a DAG). Each subgoal has an
*achievement predicate* over the environment's observation.

Built-in predicates (evaluated on one observation entry, batched):

* :class:`State` — a discrete observation equals a given state index;
* :class:`Cell` — chosen observation entries equal a grid cell ``(row, col)``;
* :class:`Circle` — chosen entries lie within ``radius`` of ``centre``;
* :class:`Box` — chosen entries lie within ``centre ± margin``.

Each compiles to one region ``lo ≤ o ≤ hi`` and ``Σ w (o − c)² ≤ r²`` so
that a batch of learners, each following its own pattern, is tested in one
vectorised expression (:class:`SubgoalTables`).

Any other condition is a :class:`Condition`: a function of the batch's
TensorDict (every entry of the step: observations of any key, flags of a
dict observation, …) returning a boolean mask. A plain function given as a
subgoal is wrapped in one, and a subgoal file names one by import path
(``{call: "package.module:function"}``).

The file format (YAML, or JSON which is valid YAML) is documented in
``docs/subgoal_files.md``; :meth:`SubgoalSeries.from_file` loads it and every
error names the file, the pattern and the field.
"""

from __future__ import annotations

import importlib
import json
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, NoReturn

import numpy as np
import torch
import yaml
from tensordict import TensorDictBase

from torchrl_subgoal import domains
from torchrl_subgoal._kernels.regions import advance_regions

__all__ = [
    "Box",
    "Cell",
    "Circle",
    "Condition",
    "Predicate",
    "RegionTables",
    "State",
    "StateAggregation",
    "SubgoalFileError",
    "SubgoalSeries",
    "SubgoalTables",
    "file_description",
    "load_patterns",
    "parse_text",
    "patterns_from_data",
    "save_patterns",
]

FORMAT = "torchrl_subgoal/v1"
#: Largest subgoal file :func:`load_patterns` reads (1 MiB, a thousand times a study's file).
MAX_FILE_BYTES = 1 << 20
#: Most subgoals one pattern of a file may have.
MAX_SUBGOALS = 1000


class SubgoalFileError(ValueError):
    """A subgoal file or pattern is malformed; the message names file, pattern and field.

    Examples:
        >>> try:
        ...     SubgoalSeries([], name="mine", source="f.yaml")
        ... except SubgoalFileError as error:
        ...     print(error)
        f.yaml: pattern 'mine': a pattern needs at least one subgoal
    """


def _where(source: str | None, pattern: str | None, field_: str) -> str:
    parts = [source or "<subgoals>"]
    if pattern is not None:
        parts.append(f"pattern {pattern!r}")
    if field_:
        parts.append(field_)
    return ": ".join(parts)


# --------------------------------------------------------------------------- reading files


class _Mapping(dict):
    """A parsed mapping that remembers the keys it held more than once (and their lines)."""

    duplicates: list[tuple[Any, int | None]]

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.duplicates = []


class _AliasError(Exception):
    def __init__(self, line: int) -> None:
        super().__init__(line)
        self.line = line


_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's parser when present
_STR, _INT = "tag:yaml.org,2002:str", "tag:yaml.org,2002:int"


def _load_yaml(text: str) -> Any:
    """Parse YAML with the safe loader's parser and resolver, then build the Python values
    in one walk over the nodes: mappings remember duplicate keys, and a node met twice
    (a YAML alias, whose re-use would let a small file expand without bound) is refused."""
    loader = _YAML_LOADER(text)
    try:
        root = loader.get_single_node()
        seen: set[int] = set()

        def build(node: yaml.Node) -> Any:
            if id(node) in seen:
                raise _AliasError(node.start_mark.line + 1)
            seen.add(id(node))
            if isinstance(node, yaml.ScalarNode):
                if node.tag == _STR:
                    return node.value
                if node.tag == _INT and node.value.isdigit():
                    return int(node.value)
                return loader.construct_object(node, deep=True)  # floats, bools, nulls, other ints
            if isinstance(node, yaml.SequenceNode):
                return [build(child) for child in node.value]
            if node.tag != "tag:yaml.org,2002:map":
                return loader.construct_object(node, deep=True)  # sets, ordered maps: refused later
            mapping = _Mapping()
            for key_node, value_node in node.value:
                key = build(key_node)
                try:
                    if key in mapping:
                        mapping.duplicates.append((key, key_node.start_mark.line + 1))
                except TypeError:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"unhashable key {key!r}", key_node.start_mark
                    ) from None
                mapping[key] = build(value_node)
            return mapping

        return None if root is None else build(root)
    finally:
        loader.dispose()


def _json_pairs(pairs: list[tuple[str, Any]]) -> _Mapping:
    mapping = _Mapping(pairs)
    if len(mapping) != len(pairs):
        seen: set[str] = set()
        mapping.duplicates = [(k, None) for k, _ in pairs if k in seen or seen.add(k)]  # type: ignore[func-returns-value]
    return mapping


def parse_text(text: str | bytes, source: str = "<subgoals>") -> Any:
    """Parse the YAML or JSON text of a subgoal file, in time linear in its size.

    JSON goes through :mod:`json`; other text through libyaml's safe loader.
    Mappings remember duplicate keys (see :func:`patterns_from_data`, which refuses
    them); YAML aliases are refused. Bytes must be UTF-8.

    Raises:
        SubgoalFileError: the text is larger than :data:`MAX_FILE_BYTES`, not UTF-8,
            or not valid YAML/JSON; the message names ``source``.

    Examples:
        >>> parse_text("patterns: {p: {subgoals: [{cell: [3, 6]}]}}")["patterns"]["p"]
        {'subgoals': [{'cell': [3, 6]}]}
    """
    if len(text) > MAX_FILE_BYTES:
        raise SubgoalFileError(
            f"{source}: larger than {MAX_FILE_BYTES} bytes, the limit for a subgoal file; "
            "split it into several files"
        )
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise SubgoalFileError(
                f"{source}: not a text file (byte {exc.object[exc.start]:#04x} at offset {exc.start} "
                "is not UTF-8); a subgoal file is YAML or JSON text"
            ) from None
    if text.lstrip().startswith("{"):
        try:
            return json.loads(text, object_pairs_hook=_json_pairs)
        except ValueError:
            pass  # YAML flow style, or broken: the YAML parser says where
        except RecursionError:
            raise SubgoalFileError(f"{source}: nested too deeply to be a subgoal file") from None
    try:
        return _load_yaml(text)
    except _AliasError as exc:
        raise SubgoalFileError(
            f"{source}: line {exc.line}: this value is used again through a YAML alias (*name); "
            "aliases are not supported in subgoal files, write the value out"
        ) from None
    except yaml.YAMLError as exc:
        message = " ".join(str(exc).split())
        raise SubgoalFileError(f"{source}: not valid YAML/JSON: {message}") from None
    except RecursionError:
        raise SubgoalFileError(f"{source}: nested too deeply to be a subgoal file") from None


def _read_file(path: Path) -> bytes:
    """At most :data:`MAX_FILE_BYTES` + 1 bytes of ``path`` (also for FIFOs and devices)."""
    try:
        with open(path, "rb") as handle:
            return handle.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise SubgoalFileError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _unique(mapping: Any, where: str, what: str) -> None:
    """Refuse a parsed mapping that held a key twice (YAML and JSON both keep the last one)."""
    duplicates = getattr(mapping, "duplicates", None)
    if duplicates:
        key, line = duplicates[0]
        at = f" (line {line})" if line else ""
        raise SubgoalFileError(f"{where}: duplicate {what} {key!r}{at}; each must appear once")


# --------------------------------------------------------------------------- predicates


@dataclass(frozen=True)
class Region:
    """A predicate compiled over an observation of ``size`` entries (see module doc).

    Examples:
        >>> region = Cell(4, 9).region(2)
        >>> region.lo.tolist(), region.hi.tolist()
        ([4.0, 9.0], [4.0, 9.0])
    """

    lo: torch.Tensor
    hi: torch.Tensor
    centre: torch.Tensor
    weight: torch.Tensor
    radius2: float


class Predicate:
    """Base class of achievement predicates.

    A predicate either compiles to a :class:`Region` of one observation entry
    (the built-ins: override :meth:`region` and :meth:`dims`), or is a
    *condition* on the step's TensorDict: override :meth:`__call__` to return
    a boolean mask of the batch (see :class:`Condition`).

    Examples:
        >>> cell = Cell(4, 9)
        >>> isinstance(cell, Predicate), cell.compiled, cell.to_dict()
        (True, True, {'cell': [4, 9]})
    """

    kind: str = "predicate"

    @property
    def compiled(self) -> bool:
        """Whether the predicate is a region (else it is called on the TensorDict)."""
        return type(self).region is not Predicate.region

    def __call__(self, tensordict: TensorDictBase) -> torch.Tensor:
        """The mask ``[*B]`` (or ``[*B, 1]``) of rows of ``tensordict`` that achieve the subgoal."""
        raise NotImplementedError(f"{type(self).__name__} is a region predicate; SubgoalTables evaluates it")

    def dims(self) -> tuple[int, ...]:
        """Observation entries the predicate reads."""
        return ()

    def region(self, size: int, one_hot: bool = False) -> Region:
        """Compile to a :class:`Region` over an observation with ``size`` entries."""
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        """The predicate as it appears in a subgoal file."""
        raise NotImplementedError

    def _open_region(self, size: int) -> tuple[torch.Tensor, torch.Tensor]:
        lo = torch.full((size,), -math.inf)
        hi = torch.full((size,), math.inf)
        return lo, hi


@dataclass(frozen=True)
class State(Predicate):
    """A discrete observation equals ``state``.

    Works on a scalar categorical observation (``o == state``) and on a one-hot
    observation (``o[state] == 1``).

    Examples:
        >>> State(24).to_dict()  # as in a subgoal file
        {'state': 24}
        >>> State(2).region(4, one_hot=True).lo.tolist()  # o[2] == 1 in a one-hot observation of 4
        [-inf, -inf, 1.0, -inf]
    """

    state: int
    kind = "state"

    def dims(self) -> tuple[int, ...]:
        return (0,)

    def region(self, size: int, one_hot: bool = False) -> Region:
        lo, hi = self._open_region(size)
        if one_hot:
            if not 0 <= self.state < size:
                raise IndexError(f"state {self.state} outside a one-hot observation of size {size}")
            lo[self.state] = hi[self.state] = 1.0
        else:
            lo[0] = hi[0] = float(self.state)
        return Region(lo, hi, torch.zeros(size), torch.zeros(size), math.inf)

    def to_dict(self) -> dict[str, Any]:
        return {"state": self.state}


@dataclass(frozen=True)
class Cell(Predicate):
    """Observation entries ``dims`` (default the first two) equal ``(row, col)``.

    Examples:
        >>> Cell(3, 6).to_dict()
        {'cell': [3, 6]}
        >>> Cell(3, 6, cell_dims=(1, 2)).to_dict()
        {'cell': [3, 6], 'dims': [1, 2]}
    """

    row: int
    col: int
    cell_dims: tuple[int, int] = (0, 1)
    kind = "cell"

    def dims(self) -> tuple[int, ...]:
        return self.cell_dims

    def region(self, size: int, one_hot: bool = False) -> Region:
        lo, hi = self._open_region(size)
        for d, v in zip(self.cell_dims, (self.row, self.col), strict=True):
            lo[d] = hi[d] = float(v)
        return Region(lo, hi, torch.zeros(size), torch.zeros(size), math.inf)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"cell": [self.row, self.col]}
        if self.cell_dims != (0, 1):
            out["dims"] = list(self.cell_dims)
        return out


@dataclass(frozen=True)
class Circle(Predicate):
    """Observation entries ``dims`` lie within ``radius`` of ``centre`` (boundary included).

    Examples:
        >>> Circle((0.5, 0.2), 0.04).to_dict()
        {'circle': {'centre': [0.5, 0.2], 'radius': 0.04}}
    """

    centre: tuple[float, ...]
    radius: float
    circle_dims: tuple[int, ...] | None = None
    kind = "circle"

    def dims(self) -> tuple[int, ...]:
        return self.circle_dims if self.circle_dims is not None else tuple(range(len(self.centre)))

    def region(self, size: int, one_hot: bool = False) -> Region:
        lo, hi = self._open_region(size)
        centre = torch.zeros(size)
        weight = torch.zeros(size)
        for d, c in zip(self.dims(), self.centre, strict=True):
            centre[d] = c
            weight[d] = 1.0
        return Region(lo, hi, centre, weight, self.radius**2)

    def to_dict(self) -> dict[str, Any]:
        body: dict[str, Any] = {"centre": list(self.centre), "radius": self.radius}
        if self.circle_dims is not None:
            body["dims"] = list(self.circle_dims)
        return {"circle": body}


@dataclass(frozen=True)
class Box(Predicate):
    """Observation entries ``dims`` lie within ``centre ± margin`` (per component).

    Examples:
        >>> Box((0.0, 0.0), (0.01, 0.01), (6, 7)).to_dict()
        {'box': {'centre': [0.0, 0.0], 'margin': 0.01, 'dims': [6, 7]}}
    """

    centre: tuple[float, ...]
    margin: tuple[float, ...]
    box_dims: tuple[int, ...]
    kind = "box"

    def dims(self) -> tuple[int, ...]:
        return self.box_dims

    def region(self, size: int, one_hot: bool = False) -> Region:
        lo, hi = self._open_region(size)
        for d, c, m in zip(self.box_dims, self.centre, self.margin, strict=True):
            lo[d] = c - m
            hi[d] = c + m
        return Region(lo, hi, torch.zeros(size), torch.zeros(size), math.inf)

    def to_dict(self) -> dict[str, Any]:
        margin: float | list[float] = (
            self.margin[0] if len(set(self.margin)) == 1 else list(self.margin)
        )
        return {"box": {"centre": list(self.centre), "margin": margin, "dims": list(self.box_dims)}}


def _import_path(fn: Any) -> str | None:
    """``"module:qualname"`` of a module-level function or class, else ``None``."""
    module, qualname = getattr(fn, "__module__", None), getattr(fn, "__qualname__", None)
    if not module or not qualname or "<" in qualname or module == "__main__":
        return None
    return f"{module}:{qualname}"


class Condition(Predicate):
    """A subgoal achieved where ``fn(tensordict)`` holds: any condition on the step's entries.

    ``fn`` receives the TensorDict the subgoal is tested on — the ``"next"``
    entries of an env step, batch shape ``[*B]`` — and returns a boolean mask
    ``[*B]`` (or ``[*B, 1]``). It may read any entry: another observation than
    the one the built-in predicates or the potential read, a flag of a dict
    observation, a field decoded from a packed discrete state. Conditions are
    evaluated once per step for the whole batch (a vectorised torch
    expression, not a per-env loop).

    Args:
        fn: the function (a plain function given as a subgoal is wrapped in a ``Condition``).
        name: a label for messages (default: the function's name).

    Keyword Args:
        path: the ``"module:attribute"`` import path a subgoal file names it by
            (derived for a module-level function, so :func:`save_patterns` can write it).
        args: with ``args``, the attribute at ``path`` is a factory and ``fn`` is
            ``factory(**args)`` (see :meth:`from_path`).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_subgoal import Condition
        >>> carrying = Condition(lambda td: td["inventory"] > 0, name="carrying")
        >>> carrying(TensorDict({"inventory": torch.tensor([0, 2])}, [2]))
        tensor([False,  True])
    """

    kind = "call"

    def __init__(
        self,
        fn: Callable[[TensorDictBase], torch.Tensor],
        name: str | None = None,
        *,
        path: str | None = None,
        args: Mapping[str, Any] | None = None,
    ) -> None:
        if not callable(fn):
            raise TypeError(f"a Condition needs a callable, got {type(fn).__name__}")
        self.fn = fn
        self.name = name or getattr(fn, "__name__", type(fn).__name__)
        self.args = dict(args) if args else None
        self.path = path if path is not None or self.args else _import_path(fn)

    @classmethod
    def from_path(cls, path: Any, args: Any = None, *, where: str = "call") -> Condition:
        """Import ``"package.module:function"`` (or ``"package.module.function"``); with ``args``
        (a mapping) call it with them to build the function. Errors name ``where``.

        Examples:
            >>> Condition.from_path("operator:truth").name
            'truth'
        """
        if not isinstance(path, str) or not path.strip():
            raise SubgoalFileError(f"{where}: expected an import path such as 'my_package.subgoals:carrying', "
                                   f"got {path!r}")
        if args is not None and not isinstance(args, Mapping):
            raise SubgoalFileError(f"{where}: args: expected a mapping of keyword arguments, got {args!r}")
        module_name, sep, attr = path.partition(":")
        if not sep:
            module_name, _, attr = path.rpartition(".")
        if not module_name or not attr:
            raise SubgoalFileError(f"{where}: {path!r} is not 'module:function'")
        try:
            obj: Any = importlib.import_module(module_name)
        except ImportError as exc:
            raise SubgoalFileError(f"{where}: cannot import module {module_name!r} ({exc}); is it installed "
                                   "or on PYTHONPATH?") from None
        for part in attr.split("."):
            if not hasattr(obj, part):
                raise SubgoalFileError(f"{where}: module {module_name!r} has no attribute {attr!r}")
            obj = getattr(obj, part)
        if args:
            try:
                obj = obj(**args)
            except Exception as exc:
                raise SubgoalFileError(f"{where}: {path}(**args) failed: {exc}") from None
        if not callable(obj):
            raise SubgoalFileError(f"{where}: {path!r} is not callable")
        return cls(obj, name=attr.split(".")[-1], path=f"{module_name}:{attr}", args=args)

    def __call__(self, tensordict: TensorDictBase) -> torch.Tensor:
        return self.fn(tensordict)

    def _identity(self) -> tuple[Any, ...]:
        if self.path is not None:
            return (self.path, tuple(sorted((self.args or {}).items(), key=lambda kv: kv[0])))
        return (id(self.fn),)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Condition) and self._identity() == other._identity()

    def __hash__(self) -> int:
        try:
            return hash(self._identity())
        except TypeError:  # unhashable args
            return hash(self.path)

    def __repr__(self) -> str:
        return f"Condition({self.path or self.name!r})"

    def to_dict(self) -> dict[str, Any]:
        if self.path is None:
            raise SubgoalFileError(
                f"condition {self.name!r} has no import path (a lambda or a local function): define it at "
                "module level, or pass path='module:function', to write it to a subgoal file"
            )
        out: dict[str, Any] = {"call": self.path}
        if self.args:
            out["args"] = dict(self.args)
        return out


# --------------------------------------------------------------------------- parsing


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
        torchrl_subgoal.subgoals.SubgoalFileError: alice.yaml: subgoals[0].cell: expected [row, col], got [4]
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


# --------------------------------------------------------------------------- series


def _as_predicate(subgoal: Any, where: str) -> Predicate:
    """A predicate as given, or a plain callable wrapped in a :class:`Condition`."""
    if isinstance(subgoal, Predicate):
        return subgoal
    if callable(subgoal):
        return Condition(subgoal)
    raise TypeError(f"{where}: a subgoal is a Predicate or a function of the TensorDict, got {subgoal!r}")


@dataclass(frozen=True)
class SubgoalSeries:
    """An ordered set of subgoals: a chain (total order) or a DAG (partial order).

    The abstract state ``z`` of an episode is the node reached: ``0`` at reset
    (no subgoal yet), ``i + 1`` once subgoal ``i`` was achieved. From ``z``
    the achievable subgoals are the *immediate successors* of ``z`` in the
    order (the sources of the DAG from ``z = 0``); each subgoal is achieved
    once and out-of-order visits do nothing. A chain of ``n`` subgoals thus
    has ``n + 1`` abstract states.

    Args:
        predicates: one achievement predicate per subgoal: a built-in region
            (:class:`Cell`, :class:`Circle`…), a :class:`Condition`, or any
            function of the step's TensorDict returning a boolean mask.
        order: pairs ``(i, j)`` meaning subgoal ``i`` comes before ``j``.
            ``None`` means the chain ``0 ≺ 1 ≺ … ≺ n-1``. Transitive pairs are
            allowed; only the covering relation decides what comes next.
        names: optional names of the subgoals (as in the file).
        name: the pattern's name (e.g. ``"participant_1"``).
        source: the file it came from, for error messages.

    Examples:
        >>> from torchrl_subgoal import SubgoalSeries
        >>> from torchrl_subgoal.subgoals import Cell
        >>> series = SubgoalSeries([Cell(3, 6), Cell(7, 9)], name="hallways")
        >>> series.num_abstract_states
        3
        >>> series.successors(0), series.successors(1), series.successors(2)
        ((0,), (1,), ())
    """

    predicates: tuple[Predicate, ...]
    order: tuple[tuple[int, int], ...] | None = None
    names: tuple[str, ...] | None = None
    name: str = "pattern"
    source: str | None = field(default=None, compare=False)
    description: str | None = field(default=None, compare=False)

    def __init__(
        self,
        predicates: Sequence[Predicate | Callable[[TensorDictBase], torch.Tensor]],
        order: Iterable[tuple[int, int]] | None = None,
        names: Sequence[str] | None = None,
        name: str = "pattern",
        source: str | None = None,
        description: str | None = None,
    ) -> None:
        where = _where(source, name, "")
        preds = tuple(_as_predicate(p, f"{where}: subgoals[{i}]") for i, p in enumerate(predicates))
        n = len(preds)
        if n == 0:
            raise SubgoalFileError(f"{where}: a pattern needs at least one subgoal")
        if names is not None and len(names) != n:
            raise SubgoalFileError(f"{where}: {len(names)} names for {n} subgoals")
        if names is not None and len(set(names)) != n:
            twice = next(nm for i, nm in enumerate(names) if nm in names[:i])
            raise SubgoalFileError(f"{_where(source, name, 'subgoals')}: duplicate subgoal name {twice!r}")
        edges = None
        if order is not None:
            edges = tuple((int(a), int(b)) for a, b in order)
            for a, b in edges:
                if not (0 <= a < n and 0 <= b < n) or a == b:
                    raise SubgoalFileError(f"{where}: order: invalid pair ({a}, {b}) for {n} subgoals")
            if edges == tuple((i, i + 1) for i in range(n - 1)):
                edges = None  # the chain, stated explicitly
        object.__setattr__(self, "predicates", preds)
        object.__setattr__(self, "order", edges)
        object.__setattr__(self, "names", tuple(names) if names is not None else None)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "source", source)
        object.__setattr__(self, "description", description)
        object.__setattr__(self, "_succ", self._covering())

    # ---------------------------------------------------------------- structure

    def __len__(self) -> int:
        return len(self.predicates)

    @property
    def is_chain(self) -> bool:
        """Whether the order is total (a chain)."""
        return self.order is None

    @property
    def num_abstract_states(self) -> int:
        """``len(self) + 1``: the start plus one state per subgoal (the terminal one is extra)."""
        return len(self) + 1

    def successors(self, z: int) -> tuple[int, ...]:
        """Subgoal indices achievable next from abstract state ``z``."""
        succ: tuple[tuple[int, ...], ...] = self._succ  # type: ignore[attr-defined]
        return succ[z]

    def _covering(self) -> tuple[tuple[int, ...], ...]:
        n = len(self)
        if self.order is None:
            return tuple((z,) if z < n else () for z in range(n + 1))
        after: list[set[int]] = [set() for _ in range(n)]
        for a, b in self.order:
            after[a].add(b)
        # topological order (Kahn); what is left over lies on or after a cycle
        indegree = [0] * n
        for a in range(n):
            for b in after[a]:
                indegree[b] += 1
        sources = tuple(i for i in range(n) if indegree[i] == 0)
        topo, stack = [], list(sources)
        while stack:
            v = stack.pop()
            topo.append(v)
            for b in after[v]:
                indegree[b] -= 1
                if indegree[b] == 0:
                    stack.append(b)
        if len(topo) < n:
            self._raise_cycle(after, set(range(n)) - set(topo))
        # reach[a]: bitset of the subgoals after a, filled in reverse topological order
        reach = [0] * n
        for a in reversed(topo):
            for b in after[a]:
                reach[a] |= reach[b] | (1 << b)
        # b directly follows a when no other successor c of a comes before b
        cover = []
        for a in range(n):
            later = 0
            for c in after[a]:
                later |= reach[c]
            cover.append(tuple(sorted(b for b in after[a] if not later >> b & 1)))
        return (tuple(sorted(sources)), *cover)

    def _raise_cycle(self, after: list[set[int]], left: set[int]) -> NoReturn:
        """Name the first subgoal (by index) that lies on a cycle of the order."""
        for start in sorted(left):
            seen: set[int] = set()
            stack = [b for b in after[start] if b in left]
            while stack:
                v = stack.pop()
                if v == start:
                    names = self.names or tuple(str(i) for i in range(len(self)))
                    raise SubgoalFileError(
                        f"{_where(self.source, self.name, 'order')}: the order has a cycle through "
                        f"subgoal {names[start]!r}"
                    )
                if v not in seen:
                    seen.add(v)
                    stack.extend(b for b in after[v] if b in left)
        raise AssertionError("no cycle found among the subgoals a topological order left over")

    # ---------------------------------------------------------------- file I/O

    def to_dict(self) -> dict[str, Any]:
        """The pattern as it appears in a subgoal file (``patterns: {name: <this>}``)."""
        out: dict[str, Any] = {} if self.description is None else {"description": self.description}
        if self.order is None and self.names is None:
            return {**out, "subgoals": [p.to_dict() for p in self.predicates]}
        names = self.names or tuple(f"sg{i}" for i in range(len(self)))
        out["subgoals"] = {nm: p.to_dict() for nm, p in zip(names, self.predicates, strict=True)}
        edges = self.order if self.order is not None else tuple((i, i + 1) for i in range(len(self) - 1))
        out["order"] = [[names[a], names[b]] for a, b in edges]
        return out

    @classmethod
    def from_dict(cls, body: Any, *, name: str = "pattern", source: str | None = None) -> SubgoalSeries:
        """Parse one pattern (the value under ``patterns: {name: ...}``)."""
        where = _where(source, name, "")
        if isinstance(body, list):
            body = {"subgoals": body}
        if not isinstance(body, Mapping):
            raise SubgoalFileError(f"{where}: expected a mapping with 'subgoals', got {body!r}")
        _unique(body, where, "field")
        _check_keys(body, {"subgoals", "order", "description"}, where)
        if "subgoals" not in body:
            raise SubgoalFileError(f"{where}: missing field 'subgoals'")
        description = _description(body, _where(source, name, "description"))
        subgoals = body["subgoals"]
        if isinstance(subgoals, list | Mapping) and len(subgoals) > MAX_SUBGOALS:
            raise SubgoalFileError(
                f"{_where(source, name, 'subgoals')}: {len(subgoals)} subgoals; a pattern may have at "
                f"most {MAX_SUBGOALS}"
            )
        if isinstance(subgoals, list):
            if "order" in body:
                raise SubgoalFileError(
                    f"{_where(source, name, 'order')}: a list of subgoals is already a total order; "
                    "name the subgoals (a mapping) to give a partial order"
                )
            preds = [parse_predicate(s, _where(source, name, f"subgoals[{i}]")) for i, s in enumerate(subgoals)]
            return cls(preds, name=name, source=source, description=description)
        if not isinstance(subgoals, Mapping):
            raise SubgoalFileError(f"{_where(source, name, 'subgoals')}: expected a list or a mapping")
        _unique(subgoals, _where(source, name, "subgoals"), "subgoal name")
        names = [str(k) for k in subgoals]
        preds = [parse_predicate(subgoals[k], _where(source, name, f"subgoals.{k}")) for k in subgoals]
        if "order" not in body:
            raise SubgoalFileError(
                f"{_where(source, name, 'order')}: missing; named subgoals need an 'order' "
                "(a list of [before, after] pairs, [] for no constraint)"
            )
        index = {nm: i for i, nm in enumerate(names)}
        order = []
        raw_order = body["order"]
        if not isinstance(raw_order, list):
            raise SubgoalFileError(f"{_where(source, name, 'order')}: expected a list of [before, after] pairs")
        for i, pair in enumerate(raw_order):
            w = _where(source, name, f"order[{i}]")
            if not isinstance(pair, list | tuple) or len(pair) != 2:
                raise SubgoalFileError(f"{w}: expected [before, after], got {pair!r}")
            for p in pair:
                if str(p) not in index:
                    raise SubgoalFileError(f"{w}: unknown subgoal {p!r}; known: {names}")
            order.append((index[str(pair[0])], index[str(pair[1])]))
        return cls(preds, order=order, names=names, name=name, source=source, description=description)

    @classmethod
    def from_file(
        cls, path: str | Path, pattern: str | None = None, *, domain: str | None = None
    ) -> SubgoalSeries:
        """Load one named pattern from a subgoal file.

        Args:
            path: a YAML or JSON subgoal file (see ``docs/subgoal_files.md``).
            pattern: the pattern's name; may be omitted when the file has one.
            domain: check subgoals against this domain's map (defaults to the
                file's ``domain`` field); see :func:`load_patterns`.
        """
        patterns = load_patterns(path, domain=domain)
        if pattern is None:
            if len(patterns) != 1:
                raise SubgoalFileError(
                    f"{path}: holds {len(patterns)} patterns {sorted(patterns)}; pass pattern=<name>"
                )
            return next(iter(patterns.values()))
        if pattern not in patterns:
            raise SubgoalFileError(f"{path}: no pattern {pattern!r}; available: {sorted(patterns)}")
        return patterns[pattern]

    @classmethod
    def random(
        cls,
        candidates: Sequence[Predicate],
        num_subgoals: int,
        generator: torch.Generator,
        *,
        name: str = "random",
    ) -> SubgoalSeries:
        """A chain of ``num_subgoals`` distinct predicates drawn from ``candidates``.

        This is the random-subgoal baseline (RRS): for a grid, the candidates
        are the free cells; for a continuous map, circles at free positions.
        """
        if num_subgoals > len(candidates):
            raise ValueError(f"cannot draw {num_subgoals} subgoals from {len(candidates)} candidates")
        picks = torch.randperm(len(candidates), generator=generator)[:num_subgoals].tolist()
        return cls([candidates[i] for i in picks], name=name)


DomainCheck = Callable[[Predicate], "str | None"]


def _domain_check(domain: str) -> DomainCheck | None:
    """The map check of the domain registered as ``domain`` (:mod:`torchrl_subgoal.domains`)."""
    try:
        return domains.get(domain).check_subgoal
    except domains.UnknownDomainError as exc:
        raise SubgoalFileError(str(exc)) from None


def load_patterns(path: str | Path, *, domain: str | None = None) -> dict[str, SubgoalSeries]:
    """Load every named pattern of a subgoal file.

    The file holds ``patterns: {name: {subgoals: [...], order: [...]}}`` and
    optionally ``domain: four_rooms`` (or ``pinball``, ``pick_and_place``, or any
    domain registered with :func:`torchrl_subgoal.domains.register`), which
    checks every subgoal against that domain's map (a cell in a wall or off the
    grid, a circle off the table, a box entry outside the observation).

    Loading takes time linear in the file's size. Files larger than
    :data:`MAX_FILE_BYTES` (1 MiB) are refused, as are patterns of more than
    :data:`MAX_SUBGOALS` subgoals, a pattern, subgoal or field named twice, YAML
    aliases, and files that are not UTF-8 text.

    Raises:
        SubgoalFileError: naming the file, the pattern and the field.

    Examples:
        >>> import os, tempfile
        >>> path = os.path.join(tempfile.mkdtemp(), "mine.yaml")
        >>> save_patterns(path, {"hallways": SubgoalSeries([Cell(3, 6), Cell(7, 9)])}, domain="four_rooms")
        >>> load_patterns(path)["hallways"].predicates
        (Cell(row=3, col=6, cell_dims=(0, 1)), Cell(row=7, col=9, cell_dims=(0, 1)))
    """
    path = Path(path)
    return patterns_from_data(parse_text(_read_file(path), str(path)), str(path), domain=domain)


def patterns_from_data(
    data: Any, source: str = "<subgoals>", *, domain: str | None = None
) -> dict[str, SubgoalSeries]:
    """:func:`load_patterns` for a file's already parsed content (see :func:`parse_text`).

    Args:
        data: the parsed YAML/JSON document.
        source: the file's name, for error messages.
        domain: as for :func:`load_patterns`.

    Examples:
        >>> text = '{"domain": "four_rooms", "patterns": {"p": {"subgoals": [{"cell": [3, 6]}]}}}'
        >>> patterns_from_data(parse_text(text, "mine.yaml"), "mine.yaml")["p"].predicates
        (Cell(row=3, col=6, cell_dims=(0, 1)),)
    """
    if not isinstance(data, Mapping):
        raise SubgoalFileError(f"{source}: expected a mapping with a 'patterns' field")
    _unique(data, source, "field")
    _check_keys(data, {"format", "domain", "observation_key", "description", "patterns"}, source)
    _description(data, f"{source}: description")
    if "format" in data and data["format"] != FORMAT:
        raise SubgoalFileError(f"{source}: format: expected {FORMAT!r}, got {data['format']!r}")
    raw = data.get("patterns")
    if not isinstance(raw, Mapping) or not raw:
        raise SubgoalFileError(f"{source}: patterns: expected a non-empty mapping of name -> pattern")
    _unique(raw, f"{source}: patterns", "pattern name")
    domain = domain if domain is not None else data.get("domain")
    try:
        check = _domain_check(str(domain)) if domain is not None else None
    except SubgoalFileError as exc:
        raise SubgoalFileError(f"{source}: domain: {exc}") from None
    patterns: dict[str, SubgoalSeries] = {}
    for name, body in raw.items():
        if str(name) in patterns:  # e.g. 1 and "1"
            raise SubgoalFileError(f"{source}: patterns: duplicate pattern name {str(name)!r}")
        series = SubgoalSeries.from_dict(body, name=str(name), source=source)
        if check is not None:
            labels = series.names or tuple(f"subgoals[{i}]" for i in range(len(series)))
            for label, pred in zip(labels, series.predicates, strict=True):
                problem = check(pred)
                if problem:
                    field_ = label if label.startswith("subgoals[") else f"subgoals.{label}"
                    raise SubgoalFileError(f"{_where(source, str(name), f'{field_}.{pred.kind}')}: {problem}")
        patterns[str(name)] = series
    return patterns


def save_patterns(
    path: str | Path,
    patterns: Mapping[str, SubgoalSeries],
    *,
    domain: str | None = None,
    description: str | None = None,
) -> None:
    """Write patterns to a subgoal file that :func:`load_patterns` reads back.

    Args:
        path: the file to write (YAML).
        patterns: name -> series; each series' ``description`` is written with it.
        domain: the file's ``domain`` (checked when it is loaded), if given.
        description: the file's ``description`` (see :func:`file_description`), if given.

    Examples:
        >>> import tempfile, pathlib
        >>> from torchrl_subgoal.subgoals import Cell
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "mine.yaml"
        >>> series = SubgoalSeries([Cell(3, 6)], name="p", description="the west hallway")
        >>> save_patterns(path, {"p": series}, domain="four_rooms", description="my subgoals")
        >>> load_patterns(path)["p"].description, file_description(path)
        ('the west hallway', 'my subgoals')
    """
    data: dict[str, Any] = {"format": FORMAT}
    if domain is not None:
        data["domain"] = domain
    if description is not None:
        data["description"] = description
    data["patterns"] = {name: s.to_dict() for name, s in patterns.items()}
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False))


def file_description(path: str | Path) -> str | None:
    """The ``description`` field of a subgoal file (``None`` if it has none); the file must load.

    Raises:
        SubgoalFileError: as :func:`load_patterns`.

    Examples:
        >>> import tempfile, pathlib
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "mine.yaml"
        >>> save_patterns(path, {"p": SubgoalSeries([State(3)])}, description="drawn by hand")
        >>> file_description(path)
        'drawn by hand'
    """
    path = Path(path)
    data = parse_text(_read_file(path), str(path))
    patterns_from_data(data, str(path))
    return _description(data, f"{path}: description")


# --------------------------------------------------------------------------- batched evaluation


def _misfit(pred: Predicate, size: int, one_hot: bool) -> str | None:
    """Why ``pred`` cannot read an observation of ``size`` entries (one-hot or not), or None.

    A ``state`` predicate reads a scalar state index or a one-hot vector; on any other
    observation it would silently compare entry 0 (e.g. a cell's row). The others read
    entries by index, which must exist and must not be a one-hot code.
    """
    if pred.kind == "state":
        return None if one_hot or size == 1 else "a state predicate reads a scalar state index or a one-hot state"
    if one_hot:
        return f"a {pred.kind} predicate reads entries by position, not a one-hot code,"
    beyond = [d for d in pred.dims() if d >= size]
    return f"reads entry {beyond[0]}" if beyond else None


class RegionTables(NamedTuple):
    """Regions as the compiled region search reads them (:func:`~torchrl_subgoal._kernels.regions.region_search`).

    Learner ``b`` follows pattern ``pattern[b]`` (pattern 0 for every learner when ``pattern`` is
    empty). From abstract state ``z`` it moves to ``j + offset`` for the first region ``j`` that
    ``succ[p, z]`` allows and that contains the observation, and stays in ``z`` when none does.
    :meth:`SubgoalTables.kernel_state` gives a subgoal series' (``offset`` 1), and
    :meth:`StateAggregation.from_regions` a region aggregation's (``offset`` 0, every region allowed).

    Examples:
        >>> import torch
        >>> tables = SubgoalTables([SubgoalSeries([State(1), State(3)])], torch.zeros(2, dtype=torch.long), 1)
        >>> regions = tables.kernel_state()
        >>> regions.lo.shape, regions.succ.shape, regions.offset  # [P, J, D], [P, J + 1, J]
        ((1, 2, 1), (1, 3, 2), 1)
    """

    pattern: np.ndarray  #: ``[N]`` int64 pattern of every learner (empty: all follow pattern 0)
    lo: np.ndarray  #: ``[P, J, D]`` float32 lower bounds (``+inf``: padding, never inside)
    hi: np.ndarray  #: ``[P, J, D]`` float32 upper bounds
    centre: np.ndarray  #: ``[P, J, D]`` float32 circle centres
    weight: np.ndarray  #: ``[P, J, D]`` float32 weights of the circle's distance (0: not read)
    radius2: np.ndarray  #: ``[P, J]`` float32 squared radii (``inf``: no circle)
    succ: np.ndarray  #: ``[P, Z, J]`` bool: which regions count from each abstract state
    offset: int  #: ``z`` of region ``j`` is ``j + offset``


class SubgoalTables:
    """Subgoal series of a batch of learners, compiled for one vectorised test.

    Each learner ``b`` follows pattern ``pattern_index[b]``. The tables hold,
    per pattern, every region predicate (padded to the longest pattern) and
    which subgoals are achievable from each abstract state; conditions
    (:class:`Condition`) are called once per step on the step's TensorDict.

    Args:
        patterns: the distinct patterns.
        pattern_index: the pattern of each learner, shape ``batch_shape``.
        observation_size: entries of the observation the region predicates read.
        one_hot: the observation is one-hot (for :class:`State` predicates).
        observation_key: for error messages.

    Examples:
        >>> import torch
        >>> from torchrl_subgoal import State, SubgoalSeries
        >>> tables = SubgoalTables([SubgoalSeries([State(1), State(3)])], torch.zeros(2, dtype=torch.long), 1)
        >>> tables.advance(torch.tensor([[0], [1]]), torch.tensor([[1], [1]])).tolist()
        [[1], [1]]
    """

    def __init__(
        self,
        patterns: Sequence[SubgoalSeries],
        pattern_index: torch.Tensor,
        observation_size: int,
        *,
        one_hot: bool = False,
        observation_key: str = "observation",
    ) -> None:
        n_nodes = max(len(p) for p in patterns)
        P, J, D = len(patterns), n_nodes, observation_size
        lo = torch.full((P, J, D), math.inf)  # padded nodes (and conditions) are never inside a region
        hi = torch.full((P, J, D), -math.inf)
        centre = torch.zeros(P, J, D)
        weight = torch.zeros(P, J, D)
        radius2 = torch.full((P, J), math.inf)
        succ = torch.zeros(P, J + 1, J, dtype=torch.bool)
        slots: dict[Predicate, torch.Tensor] = {}  # condition -> [P, J] where a pattern uses it
        for p, series in enumerate(patterns):
            for j, pred in enumerate(series.predicates):
                if not pred.compiled:
                    slots.setdefault(pred, torch.zeros(P, J, dtype=torch.bool))[p, j] = True
                    continue
                problem = _misfit(pred, D, one_hot)
                try:
                    if problem:
                        raise IndexError(problem)
                    region = pred.region(D, one_hot=one_hot)
                except IndexError as exc:
                    label = series.names[j] if series.names else f"subgoals[{j}]"
                    raise SubgoalFileError(
                        f"{_where(series.source, series.name, f'{label}.{pred.kind}')}: {exc} but the "
                        f"observation {observation_key!r} has {D} entries"
                        f"{' (one-hot)' if one_hot else ''} (wrong observation_key?)"
                    ) from None
                lo[p, j], hi[p, j] = region.lo, region.hi
                centre[p, j], weight[p, j] = region.centre, region.weight
                radius2[p, j] = region.radius2
            for z in range(len(series) + 1):
                for j in series.successors(z):
                    succ[p, z, j] = True
        idx = pattern_index.long()
        if idx.numel() and (int(idx.min()) < 0 or int(idx.max()) >= P):
            raise ValueError(f"pattern_index values must lie in [0, {P})")
        self.batch_shape = idx.shape
        self.num_states = J + 1
        self.observation_size = D
        self.observation_key = observation_key
        self.chain = all(p.is_chain for p in patterns)
        self.uses_regions = any(pred.compiled for series in patterns for pred in series.predicates)
        # per-learner tables, flattened batch first
        flat = idx.reshape(-1)
        self.lo, self.hi = lo[flat], hi[flat]
        self.centre, self.weight = centre[flat], weight[flat]
        self.radius2 = radius2[flat]
        self.succ = succ[flat]
        self.uses_circle = bool(torch.isfinite(radius2).any())
        self._rows = torch.arange(flat.numel())
        self.conditions = [(pred, where[flat]) for pred, where in slots.items()]
        # the kernels read per-pattern tables and each learner's pattern (small, stays in cache)
        self._kernel_tables = RegionTables(flat.contiguous().numpy(), lo.numpy(), hi.numpy(), centre.numpy(),
                                           weight.numpy(), radius2.numpy(), succ.numpy(), 1)

    def kernel_state(self) -> RegionTables:
        """The region tables as the compiled kernels read them (numpy, per pattern; CPU).

        Examples:
            >>> import torch
            >>> tables = SubgoalTables([SubgoalSeries([State(1)])], torch.zeros(3, dtype=torch.long), 1)
            >>> tables.kernel_state().pattern.tolist()
            [0, 0, 0]
        """
        return self._kernel_tables

    @property
    def fusable(self) -> bool:
        """Whether one compiled kernel can advance the batch (no conditions to call)."""
        return not self.conditions

    def initial(self, observation: torch.Tensor | None, batch_shape: torch.Size) -> torch.Tensor:
        """Abstract state at reset: 0 for every learner, shape ``[*batch_shape, 1]``."""
        return torch.zeros((*batch_shape, 1), dtype=torch.long)

    def rows(self, observation: torch.Tensor) -> torch.Tensor:
        """``observation`` as ``[B, D]`` rows of this batch; a ``ValueError`` if it does not fit."""
        n, d = self._rows.numel(), self.observation_size
        if observation.numel() != n * d:
            raise ValueError(
                f"observation {self.observation_key!r} of shape {tuple(observation.shape)} does not fit the subgoal "
                f"tables compiled for {n} learners x {d} entries (batch shape {tuple(self.batch_shape)})"
            )
        return observation.reshape(n, d)

    def _check_z(self, z: torch.Tensor) -> None:
        if z.numel() != self._rows.numel():
            raise ValueError(f"{z.numel()} abstract states for subgoal tables compiled for "
                             f"{self._rows.numel()} learners (batch shape {tuple(self.batch_shape)})")

    def inside(self, observation: torch.Tensor) -> torch.Tensor:
        """Which subgoal regions contain the observation, ``[B, J]`` (flattened batch)."""
        obs = self.rows(observation).unsqueeze(1).to(torch.float64)
        return _in_regions(obs, self.lo, self.hi, self.centre, self.weight, self.radius2, self.uses_circle)

    def achieved(self, observation: torch.Tensor | None, tensordict: TensorDictBase | None) -> torch.Tensor:
        """Which subgoals hold, ``[B, J]``: regions on ``observation``, conditions on ``tensordict``."""
        n = self._rows.numel()
        if self.uses_regions:
            if observation is None:
                raise ValueError(f"the region subgoals read {self.observation_key!r}, which is missing")
            hit = self.inside(observation)
        else:
            hit = torch.zeros(n, self.num_states - 1, dtype=torch.bool)
        for pred, slots in self.conditions:
            if tensordict is None:
                raise ValueError(f"condition {pred!r} needs the step's TensorDict")
            hit = hit | (slots & self._mask(pred, tensordict).unsqueeze(-1))
        return hit

    def _mask(self, pred: Predicate, tensordict: TensorDictBase) -> torch.Tensor:
        n = self._rows.numel()
        try:
            mask = pred(tensordict)
        except Exception as exc:
            raise type(exc)(f"subgoal condition {pred!r} failed on the step's TensorDict: {exc}") from exc
        if not isinstance(mask, torch.Tensor) or mask.numel() != n or mask.shape[:len(self.batch_shape)] != \
                self.batch_shape:
            shape = tuple(mask.shape) if isinstance(mask, torch.Tensor) else type(mask).__name__
            raise ValueError(f"subgoal condition {pred!r} returned {shape}; expected a boolean mask of shape "
                             f"{tuple(self.batch_shape)} (or with a trailing 1)")
        return mask.reshape(n).to(device=self.lo.device, dtype=torch.bool)

    def advance(
        self, z: torch.Tensor, observation: torch.Tensor | None, tensordict: TensorDictBase | None = None
    ) -> torch.Tensor:
        """Next abstract state after observing ``observation`` (and ``tensordict``) in abstract state ``z``.

        On the CPU without conditions this is one fused kernel; else :meth:`advance_eager`.
        """
        self._check_z(z)
        if z.device.type != "cpu" or not self.fusable:
            return self.advance_eager(z, observation, tensordict)
        assert observation is not None
        n = self._rows.numel()
        zf = z.numpy().reshape(n, 1)
        obs = self.rows(observation).numpy()
        out = np.empty((n, 1), dtype=np.int64)
        advance_regions(self._kernel_tables, zf, obs, out)
        result = torch.from_numpy(out)
        return result if result.shape == z.shape else result.view(z.shape)

    def advance_eager(
        self, z: torch.Tensor, observation: torch.Tensor | None, tensordict: TensorDictBase | None = None
    ) -> torch.Tensor:
        """:meth:`advance` with torch operations only (any device; the reference)."""
        self._check_z(z)
        zf = z.reshape(-1)
        if self.chain and self.fusable:
            # only subgoal z can be achieved next: test that one region
            assert observation is not None
            j = zf.clamp(max=self.num_states - 2)
            obs = self.rows(observation).to(torch.float64)
            rows = self._rows
            hit = _in_regions(obs, self.lo[rows, j], self.hi[rows, j], self.centre[rows, j],
                              self.weight[rows, j], self.radius2[rows, j], self.uses_circle)
            hit = hit & self.succ[self._rows, zf, j]
            return (zf + hit.long()).view_as(z)
        cand = self.succ[self._rows, zf] & self.achieved(observation, tensordict)
        first = cand.long().argmax(-1)  # lowest-index achievable subgoal
        return torch.where(cand.any(-1), first + 1, zf).view_as(z)


def _in_regions(obs: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor, centre: torch.Tensor,
                weight: torch.Tensor, radius2: torch.Tensor, circles: bool) -> torch.Tensor:
    """``_in_region`` in torch: the same float64 comparisons, summed in the same order,
    so both paths agree on every input (NaN is never inside; unread entries never matter)."""
    hit = ((obs >= lo) & (obs <= hi)).all(-1)
    if circles:
        diff = obs - centre.to(torch.float64)
        w = weight.to(torch.float64)
        terms = torch.where(w != 0, w * diff * diff, 0.0)
        d2 = torch.zeros(terms.shape[:-1], dtype=torch.float64, device=terms.device)
        for d in range(terms.shape[-1]):  # in order, as the kernel adds them
            d2 = d2 + terms[..., d]
        hit = hit & (d2 <= radius2)
    return hit


class StateAggregation:
    """A hand-given aggregation ``z = g(s)`` (the SARSA-RS baseline).

    Args:
        mapping: a lookup tensor indexed by a discrete observation, or a
            function from an observation batch ``[*B, D]`` to integer states ``[*B]``.
        num_states: number of abstract states.

    Use :meth:`from_regions` for regions of a continuous observation.

    Examples:
        >>> import torch
        >>> from torchrl_subgoal import StateAggregation
        >>> rooms = StateAggregation(torch.tensor([0, 0, 1, 1]), num_states=2)
        >>> rooms.advance(torch.zeros(3, 1, dtype=torch.long), torch.tensor([0, 2, 3]))
        tensor([[0],
                [1],
                [1]])
    """

    def __init__(
        self,
        mapping: torch.Tensor | Callable[[torch.Tensor], torch.Tensor] | None,
        num_states: int,
    ) -> None:
        self.mapping = mapping
        self.num_states = int(num_states)
        self.regions: RegionTables | None = None  # from_regions: the regions, as the kernels read them
        if isinstance(mapping, torch.Tensor):
            if mapping.dtype != torch.long or mapping.ndim != 1:
                raise ValueError("a lookup aggregation must be a 1-D long tensor indexed by state")
            if int(mapping.min()) < 0 or int(mapping.max()) >= self.num_states:
                raise ValueError(f"aggregation values must lie in [0, {self.num_states})")

    @classmethod
    def from_regions(cls, regions: Sequence[Predicate], observation_size: int) -> StateAggregation:
        """``z`` = the first of ``regions`` containing the observation (kept when none does).

        Examples:
            >>> from torchrl_subgoal import Box, StateAggregation
            >>> thirds = StateAggregation.from_regions(
            ...     [Box((c,), (1 / 6,), (0,)) for c in (1 / 6, 1 / 2, 5 / 6)], observation_size=4)
            >>> thirds.advance(torch.zeros(2, 1, dtype=torch.long), torch.tensor([[0.2, 0, 0, 0], [0.9, 0, 0, 0]]))
            tensor([[0],
                    [2]])
        """
        if not regions:
            raise ValueError("from_regions needs at least one region")
        compiled = [p.region(observation_size) for p in regions]
        agg = cls(None, len(regions))
        j = len(compiled)

        def table(name: str) -> np.ndarray:
            return torch.stack([getattr(r, name) for r in compiled])[None].numpy()  # [1, J, D]: one pattern

        agg.regions = RegionTables(  # every region allowed from every z; region j is z = j
            np.zeros(0, np.int64), table("lo"), table("hi"), table("centre"), table("weight"),
            np.array([[r.radius2 for r in compiled]], dtype=np.float32), np.ones((1, j, j), np.bool_), 0)
        return agg

    def _g(self, observation: torch.Tensor, batch_shape: torch.Size) -> torch.Tensor:
        if isinstance(self.mapping, torch.Tensor):
            return self.mapping[observation.long().reshape(batch_shape)]
        assert self.mapping is not None
        return self.mapping(observation).long().reshape(batch_shape)

    def _in_regions(self, z: torch.Tensor, observation: torch.Tensor) -> torch.Tensor:
        assert self.regions is not None
        n = z.numel()
        out = np.empty((n, 1), dtype=np.int64)
        advance_regions(self.regions, z.numpy().reshape(n, 1), observation.cpu().numpy().reshape(n, -1), out)
        return torch.from_numpy(out).view(z.shape).to(z.device)

    def initial(self, observation: torch.Tensor | None, batch_shape: torch.Size) -> torch.Tensor:
        """Abstract state of the reset observation, ``[*batch_shape, 1]``."""
        if observation is None:
            raise ValueError("a state aggregation needs the observation it reads")
        if self.regions is not None:
            return self._in_regions(torch.zeros((*batch_shape, 1), dtype=torch.long), observation)
        return self._g(observation, batch_shape).unsqueeze(-1)

    @property
    def fusable(self) -> bool:
        """Whether the fused kernels can shape with it (always: it is evaluated before them)."""
        return True

    def advance(
        self, z: torch.Tensor, observation: torch.Tensor | None, tensordict: TensorDictBase | None = None
    ) -> torch.Tensor:
        """``g`` of the new observation (the previous ``z`` matters only outside every region)."""
        if observation is None:
            raise ValueError("a state aggregation needs the observation it reads")
        if self.regions is not None:
            return self._in_regions(z, observation)
        return self._g(observation, z.shape[:-1]).unsqueeze(-1)
