"""The domain registry: one :class:`Domain` record per environment, looked up by name.

A domain registers what the subgoal files need (its env factory and the check
a subgoal must pass on its map) and, as *parts*, what each other layer needs:
the learners' set-ups (:class:`~torchrl_subgoal.training.LearnerDomain`), the
report's paper numbers and map (:class:`~torchrl_subgoal.experiments.paper.PaperResults`,
:class:`~torchrl_subgoal.experiments.plots.ReportMap`), the studio's map and
"Try it" (:class:`~torchrl_subgoal.studio.domains.StudioDomain`). Each layer
defines its own part's type and finds it with :meth:`Domain.part`; this
registry names none of them, and holds no plugin.

A subgoal file that names a domain is checked with that domain's
``check_subgoal`` when it is loaded through this module's :func:`load_patterns`
and :func:`load_pattern` (``torchrl_subgoal.load_patterns``).

Domain plugins register themselves when imported. A package makes its plugin
modules known by name under the ``torchrl_subgoal.domains`` entry-point group
(the built-in plugins, one folder each under :mod:`torchrl_subgoal.domains`, are
declared so in this package's ``pyproject.toml``): a lookup imports the module the
first time its name is asked for, so a domain whose optional dependency is missing
costs nothing until it is used. A script can also import its plugin module itself
(docs/adding_a_domain.md).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from torchrl_subgoal.subgoals.errors import SubgoalFileError
from torchrl_subgoal.subgoals.files import patterns_from_data, pick_pattern, read_file

if TYPE_CHECKING:
    from torchrl.envs import EnvBase

    from torchrl_subgoal.subgoals import Predicate, SubgoalSeries

__all__ = [
    "Domain",
    "UnknownDomainError",
    "find",
    "get",
    "having",
    "load_pattern",
    "load_patterns",
    "names",
    "part",
    "register",
    "subgoal_check",
]

T = TypeVar("T")
#: The entry-point group under which packages declare their domain plugin modules.
PLUGINS = "torchrl_subgoal.domains"
_REGISTRY: dict[str, Domain] = {}
_ALIASES: dict[str, str] = {}


class UnknownDomainError(ValueError):
    """No domain is registered under that name; the message lists the known ones.

    Examples:
        >>> get("no_such_domain")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        torchrl_subgoal.registry.UnknownDomainError: unknown domain 'no_such_domain'; known: acrobot, four_rooms, ...
    """


@dataclass(frozen=True)
class Domain:
    """One environment: what the subgoal files need of it, and each layer's own part.

    Args:
        name: the subgoal files' ``domain`` value and the name sweeps record (``"four_rooms"``).
        title: a human name.
        aliases: other names the domain is found by (the pick-and-place recipe's results say ``"fetch"``).
        make_env: ``make_env(num_envs)``: a batched env (batch size ``[num_envs]``).
        check_subgoal: why a predicate is not a valid subgoal on this domain's map, or ``None``;
            the subgoal loader runs it on every subgoal of a file that names the domain.
        parts: what other layers need of the domain, one object of each layer's own type
            (found with :meth:`part`); a part a layer does not find, it does without.

    Examples:
        >>> from torchrl_subgoal import State
        >>> line = Domain("line", check_subgoal=lambda p: None if p.kind == "state" else "states only", parts=(1.5,))
        >>> line.check_subgoal(State(3)) is None, line.part(float), line.part(str)
        (True, 1.5, None)
    """

    name: str
    title: str = ""
    aliases: tuple[str, ...] = ()
    make_env: Callable[[int], EnvBase] | None = None
    check_subgoal: Callable[[Predicate], str | None] | None = None
    parts: tuple[Any, ...] = ()

    def part(self, kind: type[T]) -> T | None:
        """The part of type ``kind`` this domain registered (``None``: none).

        Examples:
            >>> Domain("line", parts=("a note",)).part(str)
            'a note'
        """
        return next((p for p in self.parts if isinstance(p, kind)), None)


def register(domain: Domain) -> Domain:
    """Make ``domain`` known by its name and aliases (replacing an earlier one of that name).

    Examples:
        >>> line = register(Domain("line_example", title="A line"))
        >>> get("line_example").title
        'A line'
    """
    _REGISTRY[domain.name] = domain
    for alias in domain.aliases:
        _ALIASES[alias] = domain.name
    return domain


def _plugins() -> dict[str, str]:
    """Every declared plugin module, by the names it is declared under."""
    return {entry.name: entry.value for entry in entry_points(group=PLUGINS)}


def names() -> list[str]:
    """The known domains' names: the declared plugins', then those registered since.

    Examples:
        >>> names()[:4]
        ['acrobot', 'four_rooms', 'four_rooms_step', 'mountain_car']
    """
    declared = list(_plugins())
    return [*declared, *(n for n in _REGISTRY if n not in declared)]


def find(name: str) -> Domain | None:
    """The domain registered as ``name`` (a declared plugin is imported now), or ``None``.

    A name that is neither registered nor declared may be an alias a plugin registers: every declared
    plugin is imported then.

    Examples:
        >>> find("four_rooms").title, find("toy") is None
        ('Four rooms', True)
    """
    if _ALIASES.get(name, name) not in _REGISTRY:
        plugins = _plugins()
        for module in [plugins[name]] if name in plugins else plugins.values():
            importlib.import_module(module)
    return _REGISTRY.get(_ALIASES.get(name, name))


def get(name: str) -> Domain:
    """The domain registered as ``name``.

    Raises:
        UnknownDomainError: naming the known domains.

    Examples:
        >>> get("pinball").make_env(2).batch_size
        torch.Size([2])
    """
    domain = find(name)
    if domain is None:
        raise UnknownDomainError(f"unknown domain {name!r}; known: {', '.join(names())}")
    return domain


def having(kind: type) -> list[str]:
    """The known domains that registered a part of type ``kind`` (declared plugins are imported now).

    Examples:
        >>> from torchrl_subgoal.training import LearnerDomain
        >>> having(LearnerDomain)
        ['acrobot', 'four_rooms', 'four_rooms_step', 'mountain_car', 'pinball', 'point_maze_medium', 'point_maze_umaze']
    """
    return [n for n in names() if (domain := find(n)) is not None and domain.part(kind) is not None]


def part(name: str, kind: type[T]) -> T:
    """The part of type ``kind`` of the domain ``name``.

    Raises:
        ValueError: the domain is unknown, or registered no such part; the message lists those that did.

    Examples:
        >>> from torchrl_subgoal.training import LearnerDomain
        >>> part("four_rooms", LearnerDomain).subgoal_key
        'cell'
        >>> part("pick_and_place", LearnerDomain)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: domain 'pick_and_place' registered no LearnerDomain; the domains that did: acrobot, four_rooms, ...
        >>> part("cartpole", LearnerDomain)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: unknown domain 'cartpole'; the domains with a LearnerDomain: acrobot, four_rooms, ...
    """
    domain = find(name)
    found = domain.part(kind) if domain is not None else None
    if found is None:
        if domain is None:
            raise ValueError(f"unknown domain {name!r}; the domains with a {kind.__name__}: {', '.join(having(kind))}")
        raise ValueError(
            f"domain {name!r} registered no {kind.__name__}; the domains that did: {', '.join(having(kind))}"
        )
    return found


def subgoal_check(name: str) -> Callable[[Predicate], str | None] | None:
    """The map check of the domain registered as ``name`` (``None``: it has none): what a subgoal file
    naming that domain is checked with.

    Raises:
        UnknownDomainError: naming the known domains.

    Examples:
        >>> from torchrl_subgoal import Cell
        >>> subgoal_check("four_rooms")(Cell(0, 6))
        '(0, 6) is a wall'
    """
    return get(name).check_subgoal


def load_patterns(path: str | Path, *, domain: str | None = None) -> dict[str, SubgoalSeries]:
    """Load every named pattern of a subgoal file, each subgoal checked against its domain's map.

    The domain is ``domain`` if given, else the file's ``domain`` field (none: no check); its
    ``check_subgoal`` runs on every subgoal (a cell in a wall or off the grid, a circle off the
    table, a box entry outside the observation). Otherwise as
    :func:`torchrl_subgoal.subgoals.load_patterns`.

    Raises:
        SubgoalFileError: naming the file, the pattern and the field; an unknown domain is
            reported as the file's ``domain`` error, naming the known ones.

    Examples:
        >>> import os, tempfile
        >>> from torchrl_subgoal import Cell, SubgoalSeries, save_patterns
        >>> path = os.path.join(tempfile.mkdtemp(), "mine.yaml")
        >>> save_patterns(path, {"hallways": SubgoalSeries([Cell(3, 6), Cell(0, 6)])}, domain="four_rooms")
        >>> load_patterns(path)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        torchrl_subgoal.subgoals.errors.SubgoalFileError: ...: pattern 'hallways': subgoals[1].cell: (0, 6) is a wall
    """
    data = read_file(path)
    name = domain if domain is not None else data.get("domain") if isinstance(data, Mapping) else None
    try:
        check = subgoal_check(str(name)) if name is not None else None
    except UnknownDomainError as exc:
        raise SubgoalFileError(f"{path}: domain: {exc}") from None
    return patterns_from_data(data, str(path), check=check)


def load_pattern(path: str | Path, pattern: str | None = None, *, domain: str | None = None) -> SubgoalSeries:
    """Load one named pattern of a subgoal file, checked as :func:`load_patterns` checks it.

    Args:
        path: a YAML or JSON subgoal file (see ``docs/subgoal_files.md``).
        pattern: the pattern's name; may be omitted when the file has one.
        domain: check the subgoals against this domain's map (defaults to the file's ``domain`` field).

    Raises:
        SubgoalFileError: as :func:`load_patterns`, or no such pattern (the message lists those there are).

    Examples:
        >>> from importlib.resources import files
        >>> path = files("torchrl_subgoal") / "domains" / "four_rooms" / "four_rooms_participants.yaml"
        >>> load_pattern(path, "participant_1").predicates[0]
        Cell(row=4, col=9, cell_dims=(0, 1))
    """
    return pick_pattern(load_patterns(path, domain=domain), pattern, str(path))
