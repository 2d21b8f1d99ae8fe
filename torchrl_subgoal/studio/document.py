"""The studio's drawings: JSON requests to and from subgoal files, validated by the subgoal loader.

A *drawing* is what the page sends: the domain, the map, and a list of
patterns, each with its name, its subgoals (a predicate as in a subgoal file,
plus an optional ``name``) and ``order`` (``null`` for the chain, else
``[before, after]`` pairs of subgoal names)::

    {"domain": "four_rooms", "map": "", "patterns": [
        {"name": "hallways", "subgoals": [{"cell": [3, 6]}, {"cell": [7, 9]}], "order": null}]}

:func:`read_drawing` turns it into the subgoal file it would save and checks
that file with :func:`torchrl_subgoal.load_patterns`, the very code
``SubgoalSeries.from_file`` and the recipes run, so whatever the studio saves
the recipes read. Every problem is a :class:`RequestError` whose message names
the file, the pattern and the field.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from torchrl_subgoal.studio.domains import Domain, FormError
from torchrl_subgoal.subgoals import (
    FORMAT,
    SubgoalFileError,
    SubgoalSeries,
    load_patterns,
    save_patterns,
)

__all__ = ["Drawing", "RequestError", "file_path", "parse_json", "read_drawing", "save_drawing", "to_document"]

MAX_REQUEST_BYTES = 256 * 1024
SUFFIXES = (".yaml", ".yml", ".json")
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,79}")


class RequestError(ValueError):
    """A bad request: the page shows the message; ``status`` is the HTTP code.

    Examples:
        >>> error = RequestError("alice.yaml: not a subgoal file", status=422)
        >>> str(error), error.status
        ('alice.yaml: not a subgoal file', 422)
    """

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


def parse_json(body: bytes) -> Any:
    """Decode a request body; duplicate keys, NaN and bad UTF-8 are errors, not silently merged.

    Examples:
        >>> parse_json(b'{"a": 1}')
        {'a': 1}
        >>> parse_json(b'{"a": 1, "a": 2}')
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.document.RequestError: request: the key 'a' appears twice in one object
    """
    if len(body) > MAX_REQUEST_BYTES:
        raise RequestError(f"request: {len(body)} bytes, over the limit of {MAX_REQUEST_BYTES}", status=413)

    def unique(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in pairs:
            if key in out:
                raise RequestError(f"request: the key {key!r} appears twice in one object")
            out[key] = value
        return out

    def constant(name: str) -> Any:
        raise RequestError(f"request: {name} is not a JSON number")

    try:
        return json.loads(body.decode("utf-8"), object_pairs_hook=unique, parse_constant=constant)
    except UnicodeDecodeError as exc:
        raise RequestError(f"request: the body is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise RequestError(f"request: not valid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None


def file_name(name: str) -> str:
    """A safe file name in the save folder: ``.yaml`` is added when no suffix is given.

    Examples:
        >>> file_name("alice"), file_name("bob.json")
        ('alice.yaml', 'bob.json')
        >>> file_name("../etc/passwd")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.document.RequestError: file name '../etc/passwd': use letters, digits, '_', '-' and '.' (at most 80, not starting with '.' or '-')
    """
    if not isinstance(name, str) or not _NAME.fullmatch(name) or ".." in name:
        raise RequestError(
            f"file name {name!r}: use letters, digits, '_', '-' and '.' (at most 80, not starting with '.' or '-')"
        )
    return name if name.lower().endswith(SUFFIXES) else f"{name}.yaml"


def file_path(folder: Path, name: str) -> Path:
    """``folder / file_name(name)``, checked to lie inside ``folder``.

    Examples:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> file_path(folder, "alice") == folder.resolve() / "alice.yaml"
        True
    """
    root = folder.resolve()
    path = (root / file_name(name)).resolve()
    if path.parent != root:
        raise RequestError(f"file name {name!r}: must name a file directly in the save folder")
    return path


@dataclass
class Drawing:
    """A checked drawing: its domain, map and patterns, ready to save or train.

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> from torchrl_subgoal.subgoals import Cell
        >>> series = SubgoalSeries([Cell(4, 9)], name="alice")
        >>> drawing = Drawing(default_domains()["four_rooms"], "", {"alice": series}, "a hallway")
        >>> drawing.domain.name, list(drawing.patterns)
        ('four_rooms', ['alice'])
    """

    domain: Domain
    map: str
    patterns: dict[str, SubgoalSeries]
    description: str | None = None


def _expect(condition: bool, message: str) -> None:
    if not condition:
        raise RequestError(message)


def _pattern_body(index: int, raw: Any, domain: Domain) -> tuple[str, dict[str, Any]]:
    """One request pattern as the file's ``patterns: {name: body}`` entry."""
    where = f"request: patterns[{index}]"
    _expect(isinstance(raw, Mapping), f"{where}: expected an object with name, subgoals and order")
    unknown = set(raw) - {"name", "subgoals", "order", "description"}
    _expect(not unknown, f"{where}: unknown field(s) {sorted(unknown)}; allowed: name, subgoals, order, description")
    described = {"description": raw["description"]} if raw.get("description") is not None else {}
    name = raw.get("name")
    _expect(isinstance(name, str) and name.strip() != "", f"{where}.name: expected a non-empty string")
    subgoals = raw.get("subgoals")
    _expect(isinstance(subgoals, list), f"{where}.subgoals: expected a list of subgoals")
    predicates, names = [], []
    for j, sg in enumerate(subgoals):
        _expect(isinstance(sg, Mapping), f"{where}.subgoals[{j}]: expected an object such as {{\"cell\": [3, 6]}}")
        label = sg.get("name")
        _expect(label is None or (isinstance(label, str) and label.strip() != ""),
                f"{where}.subgoals[{j}].name: expected a non-empty string or null")
        names.append(label)
        try:
            predicates.append(domain.from_page({k: v for k, v in sg.items() if k != "name"}, f"{where}.subgoals[{j}]"))
        except FormError as exc:
            raise RequestError(str(exc)) from None
    order = raw.get("order")
    _expect(order is None or isinstance(order, list), f"{where}.order: expected null (a chain) or a list of pairs")
    if order is None and not any(names):
        return name, {**described, "subgoals": predicates}
    full = [label or f"sg{j + 1}" for j, label in enumerate(names)]
    seen: set[str] = set()
    for label in full:
        _expect(label not in seen, f"request: pattern {name!r}: the subgoal name {label!r} is used twice")
        seen.add(label)
    chain = [[a, b] for a, b in itertools.pairwise(full)]
    return name, {**described, "subgoals": dict(zip(full, predicates, strict=True)),
                  "order": chain if order is None else order}


def _load(data: Mapping[str, Any], source: str, domain: str) -> dict[str, SubgoalSeries]:
    """Write ``data`` as the subgoal file ``source`` would be and load it with :func:`load_patterns`."""
    with tempfile.TemporaryDirectory(prefix="studio-") as tmp:
        path = Path(tmp) / source
        path.write_text(yaml.safe_dump(dict(data), sort_keys=False))
        try:
            return load_patterns(path, domain=domain)
        except SubgoalFileError as exc:
            raise RequestError(str(exc).replace(str(path), source)) from None


def read_drawing(data: Any, domains: Mapping[str, Domain], *, source: str = "drawing.yaml") -> Drawing:
    """Check a drawing (see the module doc) as the subgoal file ``source`` it would be saved as.

    Args:
        data: the decoded request.
        domains: the studio's domains by name.
        source: the file name used in messages.

    Raises:
        RequestError: naming the file (``source``), the pattern and the field.

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> wall = {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [{"cell": [0, 6]}]}]}
        >>> read_drawing(wall, default_domains())
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.document.RequestError: drawing.yaml: pattern 'p': subgoals[0].cell: (0, 6) is a wall
    """
    _expect(isinstance(data, Mapping), "request: expected a JSON object with domain, map and patterns")
    unknown = set(data) - {"domain", "map", "patterns", "file", "description"}
    _expect(not unknown,
            f"request: unknown field(s) {sorted(unknown)}; allowed: domain, map, patterns, file, description")
    domain = domains.get(str(data.get("domain")))
    _expect(domain is not None, f"request: domain: expected one of {sorted(domains)}, got {data.get('domain')!r}")
    assert domain is not None
    map_name = ""
    if domain.maps:
        map_name = data.get("map") or next(iter(domain.maps))
        _expect(map_name in domain.maps, f"request: map: expected one of {list(domain.maps)}, got {map_name!r}")
    raw = data.get("patterns")
    _expect(isinstance(raw, list) and len(raw) > 0, "request: patterns: expected a non-empty list of patterns")
    bodies: dict[str, Any] = {}
    for i, pattern in enumerate(raw):
        name, body = _pattern_body(i, pattern, domain)
        _expect(name not in bodies, f"request: patterns: the name {name!r} is used by two patterns; rename one")
        bodies[name] = body
    described = {"description": data["description"]} if data.get("description") is not None else {}
    patterns = _load({"format": FORMAT, "domain": domain.name, **described, "patterns": bodies}, source, domain.name)
    if domain.map_check is not None:
        for name, series in patterns.items():
            for j, predicate in enumerate(series.predicates):
                problem = domain.map_check(predicate, map_name, domain.maps[map_name])
                if problem:
                    label = f"subgoals.{series.names[j]}" if series.names else f"subgoals[{j}]"
                    raise RequestError(f"{source}: pattern {name!r}: {label}.{predicate.kind}: {problem}")
    return Drawing(domain, map_name, patterns, described.get("description"))


def save_drawing(drawing: Drawing, path: Path) -> None:
    """Write the drawing's patterns to ``path`` with :func:`save_patterns` (atomically).

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> from torchrl_subgoal.subgoals import Cell
        >>> from torchrl_subgoal.subgoals import load_patterns
        >>> drawing = Drawing(default_domains()["four_rooms"], "", {"alice": SubgoalSeries([Cell(4, 9)], name="alice")})
        >>> path = Path(tempfile.mkdtemp()) / "alice.yaml"
        >>> save_drawing(drawing, path)
        >>> load_patterns(path)["alice"].to_dict()
        {'subgoals': [{'cell': [4, 9]}]}
    """
    tmp = path.with_name(f".{path.name}.tmp")
    save_patterns(tmp, drawing.patterns, domain=drawing.domain.name, description=drawing.description)
    os.replace(tmp, path)


def infer_domain(patterns: Mapping[str, SubgoalSeries], domains: Mapping[str, Domain], source: str) -> Domain:
    """The first domain whose map check accepts every subgoal of ``patterns``.

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> from torchrl_subgoal.subgoals import Cell
        >>> patterns = {"alice": SubgoalSeries([Cell(4, 9)], name="alice")}
        >>> infer_domain(patterns, default_domains(), "alice.yaml").name
        'four_rooms'
    """
    predicates = [p for series in patterns.values() for p in series.predicates]
    for domain in domains.values():
        check = domain.check_subgoal
        if check is None or all(check(p) is None for p in predicates):
            return domain
    kinds = sorted({p.kind for p in predicates})
    raise RequestError(f"{source}: its subgoals ({', '.join(kinds)}) fit none of the studio's domains "
                       f"{sorted(domains)}", status=422)


def to_document(patterns: Mapping[str, SubgoalSeries], domain: Domain, source: str) -> list[dict[str, Any]]:
    """Patterns as the page edits them (the inverse of :func:`read_drawing`); ``source`` names the file.

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> from torchrl_subgoal.subgoals import Cell
        >>> patterns = {"alice": SubgoalSeries([Cell(4, 9)], name="alice")}
        >>> to_document(patterns, default_domains()["four_rooms"], "alice.yaml")
        [{'name': 'alice', 'subgoals': [{'name': None, 'cell': [4, 9]}], 'order': None, 'description': None}]
    """
    out = []
    for name, series in patterns.items():
        names: Sequence[str | None] = series.names or [None] * len(series)
        subgoals = []
        for j, (label, p) in enumerate(zip(names, series.predicates, strict=True)):
            try:
                subgoals.append({"name": label, **domain.to_page(p)})
            except FormError as exc:
                raise RequestError(f"{source}: pattern {name!r}: subgoals[{j}]: {exc}", status=422) from None
        order = None
        if series.order is not None:
            full = series.names or [f"sg{j + 1}" for j in range(len(series))]
            order = [[full[a], full[b]] for a, b in series.order]
        out.append({"name": name, "subgoals": subgoals, "order": order, "description": series.description})
    return out
