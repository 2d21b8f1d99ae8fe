"""Subgoal files: parsing YAML/JSON in linear time, loading and saving patterns, domain checks."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import yaml

from torchrl_subgoal.subgoals.errors import SubgoalFileError, _where
from torchrl_subgoal.subgoals.forms import _check_keys, _description, _unique
from torchrl_subgoal.subgoals.predicates import Predicate
from torchrl_subgoal.subgoals.series import SubgoalSeries

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


#: Why a predicate is not a valid subgoal on a domain's map (``None``: it is one).
DomainCheck = Callable[[Predicate], "str | None"]
#: How a file's ``domain`` name finds its check; the domain registry sets it (:func:`use_domain_checks`).
_domain_checks: list[Callable[[str], DomainCheck | None]] = []


def use_domain_checks(lookup: Callable[[str], DomainCheck | None]) -> None:
    """Set how a subgoal file's ``domain`` field finds the check its subgoals must pass.

    :mod:`torchrl_subgoal.domains` calls this when it is imported (importing
    ``torchrl_subgoal`` imports it), so that a file naming a registered domain
    is checked against that domain's map. ``lookup(name)`` returns the check,
    ``None`` for a domain without one, or raises ``ValueError`` (whose message
    is reported as the file's ``domain`` error) for an unknown name.

    Args:
        lookup: the domain name -> check function.

    Examples:
        >>> from torchrl_subgoal.subgoals import State
        >>> use_domain_checks(lambda name: lambda p: None if p.kind == "state" else "states only")
        >>> patterns_from_data({"domain": "line", "patterns": {"p": {"subgoals": [{"cell": [1, 2]}]}}}, "f.yaml")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.subgoals.errors.SubgoalFileError: f.yaml: pattern 'p': subgoals[0].cell: states only
        >>> from torchrl_subgoal import domains
        >>> use_domain_checks(domains.subgoal_check)  # the registry's lookup again
    """
    _domain_checks[:] = [lookup]


def _domain_check(domain: str) -> DomainCheck | None:
    """The check of the domain named ``domain``, through the lookup :func:`use_domain_checks` set."""
    if not _domain_checks:
        raise SubgoalFileError(f"unknown domain {domain!r}: no domain registry is in use (import torchrl_subgoal)")
    try:
        return _domain_checks[0](domain)
    except ValueError as exc:
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
        >>> from torchrl_subgoal import Cell
        >>> path = os.path.join(tempfile.mkdtemp(), "mine.yaml")
        >>> save_patterns(path, {"hallways": SubgoalSeries([Cell(3, 6), Cell(7, 9)])}, domain="four_rooms")
        >>> load_patterns(path)["hallways"].predicates
        (Cell(row=3, col=6, cell_dims=(0, 1)), Cell(row=7, col=9, cell_dims=(0, 1)))
    """
    path = Path(path)
    return patterns_from_data(parse_text(_read_file(path), str(path)), str(path), domain=domain)


def patterns_from_data(data: Any, source: str = "<subgoals>", *, domain: str | None = None) -> dict[str, SubgoalSeries]:
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
        >>> from torchrl_subgoal import State
        >>> save_patterns(path, {"p": SubgoalSeries([State(3)])}, description="drawn by hand")
        >>> file_description(path)
        'drawn by hand'
    """
    path = Path(path)
    data = parse_text(_read_file(path), str(path))
    patterns_from_data(data, str(path))
    return _description(data, f"{path}: description")
