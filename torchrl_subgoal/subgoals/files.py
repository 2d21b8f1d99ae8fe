"""Subgoal files: parsing YAML/JSON in linear time, reading patterns and predicates with errors that name
the file, the pattern and the field, checking subgoals against a map, and saving."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import yaml

from torchrl_subgoal.subgoals.errors import SubgoalFileError, _where
from torchrl_subgoal.subgoals.predicates import Box, Cell, Circle, Condition, Predicate, State
from torchrl_subgoal.subgoals.series import MAX_SUBGOALS, SubgoalSeries

FORMAT = "torchrl_subgoal/v1"
#: Largest subgoal file :func:`load_patterns` reads (1 MiB, a thousand times a study's file).
MAX_FILE_BYTES = 1 << 20


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
            f"{source}: larger than {MAX_FILE_BYTES} bytes, the limit for a subgoal file; split it into several files"
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


# ------------------------------------------------------------ patterns and predicates


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


def pattern_from_data(body: Any, *, name: str = "pattern", source: str | None = None) -> SubgoalSeries:
    """Parse one pattern (the value under ``patterns: {name: ...}``).

    Examples:
        >>> pattern_from_data({"subgoals": {"a": {"state": 3}, "b": {"state": 5}}, "order": []}).successors(0)
        (0, 1)
    """
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
            f"{_where(source, name, 'subgoals')}: {len(subgoals)} subgoals; a pattern may have at most {MAX_SUBGOALS}"
        )
    if isinstance(subgoals, list):
        if "order" in body:
            raise SubgoalFileError(
                f"{_where(source, name, 'order')}: a list of subgoals is already a total order; "
                "name the subgoals (a mapping) to give a partial order"
            )
        preds = [parse_predicate(s, _where(source, name, f"subgoals[{i}]")) for i, s in enumerate(subgoals)]
        return SubgoalSeries(preds, name=name, source=source, description=description)
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
    return SubgoalSeries(preds, order=order, names=names, name=name, source=source, description=description)


#: Why a predicate is not a valid subgoal on a domain's map (``None``: it is one).
DomainCheck = Callable[[Predicate], "str | None"]


def read_file(path: str | Path) -> Any:
    """The parsed content of the subgoal file ``path`` (see :func:`parse_text`), not yet checked.

    Raises:
        SubgoalFileError: the file cannot be read, or as :func:`parse_text`.

    Examples:
        >>> import tempfile, pathlib
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "mine.yaml"
        >>> _ = path.write_text("domain: four_rooms\\npatterns: {p: [{cell: [3, 6]}]}")
        >>> read_file(path)["domain"]
        'four_rooms'
    """
    path = Path(path)
    return parse_text(_read_file(path), str(path))


def load_patterns(path: str | Path, *, check: DomainCheck | None = None) -> dict[str, SubgoalSeries]:
    """Load every named pattern of a subgoal file, each subgoal checked with ``check``.

    The file holds ``patterns: {name: {subgoals: [...], order: [...]}}`` and
    optionally ``domain: four_rooms``. This function checks the subgoals only
    with the ``check`` it is given (a domain's ``check_subgoal``: a cell in a
    wall or off the grid, a circle off the table, a box entry outside the
    observation); :func:`torchrl_subgoal.load_patterns` looks the check up in
    the domain registry by the file's ``domain``.

    Loading takes time linear in the file's size. Files larger than
    :data:`MAX_FILE_BYTES` (1 MiB) are refused, as are patterns of more than
    :data:`MAX_SUBGOALS` subgoals, a pattern, subgoal or field named twice, YAML
    aliases, and files that are not UTF-8 text.

    Args:
        path: a YAML or JSON subgoal file (see ``docs/subgoal_files.md``).
        check: why a predicate is not a valid subgoal (``None``: it is one), run on every subgoal.

    Raises:
        SubgoalFileError: naming the file, the pattern and the field.

    Examples:
        >>> import os, tempfile
        >>> from torchrl_subgoal.subgoals import Cell
        >>> path = os.path.join(tempfile.mkdtemp(), "mine.yaml")
        >>> save_patterns(path, {"hallways": SubgoalSeries([Cell(3, 6), Cell(7, 9)])})
        >>> load_patterns(path)["hallways"].predicates
        (Cell(row=3, col=6, cell_dims=(0, 1)), Cell(row=7, col=9, cell_dims=(0, 1)))
        >>> load_patterns(path, check=lambda p: "not on this map" if p.row > 5 else None)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.subgoals.errors.SubgoalFileError: ...: pattern 'hallways': subgoals[1].cell: not on this map
    """
    return patterns_from_data(read_file(path), str(path), check=check)


def load_pattern(path: str | Path, pattern: str | None = None, *, check: DomainCheck | None = None) -> SubgoalSeries:
    """Load one named pattern of a subgoal file (see :func:`load_patterns`).

    Args:
        path: a YAML or JSON subgoal file.
        pattern: the pattern's name; may be omitted when the file has one.
        check: as for :func:`load_patterns`.

    Raises:
        SubgoalFileError: as :func:`load_patterns`, or no such pattern (the message lists those there are).

    Examples:
        >>> import os, tempfile
        >>> from torchrl_subgoal.subgoals import State
        >>> path = os.path.join(tempfile.mkdtemp(), "mine.yaml")
        >>> save_patterns(path, {"a": SubgoalSeries([State(3)]), "b": SubgoalSeries([State(4)])})
        >>> load_pattern(path, "b").predicates
        (State(state=4),)
    """
    return pick_pattern(load_patterns(path, check=check), pattern, str(path))


def pick_pattern(patterns: Mapping[str, SubgoalSeries], pattern: str | None, source: str) -> SubgoalSeries:
    """The pattern named ``pattern`` among a file's ``patterns`` (``None``: the file's only one).

    Raises:
        SubgoalFileError: no such pattern, or ``None`` for a file of several; the message lists them.

    Examples:
        >>> from torchrl_subgoal.subgoals import State
        >>> patterns = {"a": SubgoalSeries([State(1)]), "b": SubgoalSeries([State(2)])}
        >>> pick_pattern(patterns, "b", "f.yaml").predicates
        (State(state=2),)
        >>> pick_pattern(patterns, None, "f.yaml")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.subgoals.errors.SubgoalFileError: f.yaml: holds 2 patterns ['a', 'b']; pass pattern=<name>
    """
    if pattern is None:
        if len(patterns) != 1:
            raise SubgoalFileError(f"{source}: holds {len(patterns)} patterns {sorted(patterns)}; pass pattern=<name>")
        return next(iter(patterns.values()))
    if pattern not in patterns:
        raise SubgoalFileError(f"{source}: no pattern {pattern!r}; available: {sorted(patterns)}")
    return patterns[pattern]


def patterns_from_data(
    data: Any, source: str = "<subgoals>", *, check: DomainCheck | None = None
) -> dict[str, SubgoalSeries]:
    """:func:`load_patterns` for a file's already parsed content (see :func:`parse_text`).

    Args:
        data: the parsed YAML/JSON document.
        source: the file's name, for error messages.
        check: as for :func:`load_patterns`.

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
    patterns: dict[str, SubgoalSeries] = {}
    for name, body in raw.items():
        if str(name) in patterns:  # e.g. 1 and "1"
            raise SubgoalFileError(f"{source}: patterns: duplicate pattern name {str(name)!r}")
        series = pattern_from_data(body, name=str(name), source=source)
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
        >>> from torchrl_subgoal import State
        >>> save_patterns(path, {"p": SubgoalSeries([State(3)])}, description="drawn by hand")
        >>> file_description(path)
        'drawn by hand'
    """
    data = read_file(path)
    patterns_from_data(data, str(path))
    return _description(data, f"{path}: description")
