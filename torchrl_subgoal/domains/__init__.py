"""The domain registry: one :class:`Domain` record per environment, looked up by name.

A domain registers what the subgoal files need (its env factory and the check
a subgoal must pass on its map) and, as *parts*, what each other layer needs:
the learners' set-ups (:class:`~torchrl_subgoal.training.LearnerDomain`), the
report's paper numbers and map (:class:`~torchrl_subgoal.experiments.paper.PaperResults`,
:class:`~torchrl_subgoal.experiments.plots.ReportMap`), the studio's map and
"Try it" (:class:`~torchrl_subgoal.studio.domains.StudioDomain`). Each layer
defines its own part's type and finds it with :meth:`Domain.part`; this
registry names none of them.

A subgoal file that names a domain is checked with that domain's
``check_subgoal`` (this module sets :func:`~torchrl_subgoal.subgoals.use_domain_checks`
when imported, as ``import torchrl_subgoal`` does).

Domain plugins register themselves when imported. A package makes its plugin
modules known by name under the ``torchrl_subgoal.domains`` entry-point group
(the built-in four-rooms with its step-cost variant, PinBall, pick-and-place, PointMaze and
MountainCar plugins are declared so in this package's ``pyproject.toml``): a lookup imports
the module the first time its name is asked for, so a domain whose optional dependency is
missing costs nothing until it is used. A script can also import its plugin module itself
(docs/adding_a_domain.md).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any, TypeVar

from torchrl_subgoal.subgoals.files import use_domain_checks

if TYPE_CHECKING:
    from torchrl.envs import EnvBase

    from torchrl_subgoal.subgoals import Predicate

__all__ = ["Domain", "UnknownDomainError", "find", "get", "having", "names", "part", "register", "subgoal_check"]

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
        torchrl_subgoal.domains.UnknownDomainError: unknown domain 'no_such_domain'; known: four_rooms, ...
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
        ['four_rooms', 'four_rooms_step', 'mountain_car', 'pick_and_place']
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
        ['four_rooms', 'four_rooms_step', 'mountain_car', 'pinball', 'point_maze_medium', 'point_maze_umaze']
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
        ValueError: domain 'pick_and_place' registered no LearnerDomain; the domains that did: four_rooms, ...
        >>> part("cartpole", LearnerDomain)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: unknown domain 'cartpole'; the domains with a LearnerDomain: four_rooms, ...
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


use_domain_checks(subgoal_check)
