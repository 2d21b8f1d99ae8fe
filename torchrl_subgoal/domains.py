"""Domains register themselves: one :class:`Domain` record per environment, looked up by name.

A domain is everything the rest of the package needs to know about one
environment: how to make it, which subgoals fit its map, how to draw them,
what the paper reports for it and how the studio edits it. The core (the
subgoal loader, the report's figures and paper tables, the studio) asks this
registry by name and never imports a domain's module itself.

The built-in domains live next to their envs (``torchrl_subgoal.envs.four_rooms_domain``,
``pinball_domain``, ``fetch_domain``) and are imported on first use, so a domain
whose optional dependency is missing (pick-and-place needs MuJoCo to *run*) costs
nothing until it is used. Your own domain is one :func:`register` call (see
docs/adding_a_domain.md).
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from torchrl_subgoal.subgoals.files import use_domain_checks

if TYPE_CHECKING:
    from torchrl.envs import EnvBase

    from torchrl_subgoal.agents.loop import OnlineAgent
    from torchrl_subgoal.experiments.paper import PaperResults
    from torchrl_subgoal.subgoals import Predicate
    from torchrl_subgoal.training.domains import A2CDomain

__all__ = ["Domain", "FormError", "Limit", "UnknownDomainError", "find", "get", "having", "names", "register"]

#: ``draw_map(ax, patterns, options)``: draw the map and ``patterns`` (name -> SubgoalSeries) on a
#: matplotlib ``Axes``; ``options`` is the ``report.map`` section of a sweep's config.
MapHook = Callable[[Any, Mapping[str, Any], Mapping[str, Any]], None]
#: ``learner(learners, seed, max_steps, map)``: a fresh batched env (``max_steps`` and ``map`` ``None``:
#: the domain's own) and the paper's online learner for it, with the settings of its shaping
#: transform (``gamma``, ``value_lr``, ``observation_key``).
LearnerHook = Callable[[int, int, int | None, str | None], tuple["EnvBase", "OnlineAgent", Mapping[str, Any]]]

#: The built-in domains' names.
_BUILT_IN_NAMES = ("four_rooms", "pinball", "pick_and_place")
#: The built-in domains, by every name they are looked up by: the module that registers them.
_BUILT_IN = {
    "four_rooms": "torchrl_subgoal.envs.four_rooms_domain",
    "pinball": "torchrl_subgoal.envs.pinball_domain",
    "pick_and_place": "torchrl_subgoal.envs.fetch_domain",
    "fetch": "torchrl_subgoal.envs.fetch_domain",  # what the pick-and-place recipe's results record
}
_REGISTRY: dict[str, Domain] = {}
_ALIASES: dict[str, str] = {}


class UnknownDomainError(ValueError):
    """No domain is registered under that name; the message lists the known ones.

    Examples:
        >>> get("no_such_domain")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        torchrl_subgoal.domains.UnknownDomainError: unknown domain 'no_such_domain'; known: four_rooms, pinball, pick_and_place...
    """


class FormError(ValueError):
    """A subgoal the studio's page sent (or a file holds) that the domain's form cannot express;
    the message says where.

    Examples:
        >>> raise FormError("patterns.p.subgoals[0].box.components: expected a non-empty list")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.domains.FormError: patterns.p.subgoals[0].box.components: expected a non-empty list
    """


@dataclass(frozen=True)
class Limit:
    """Bounds of one "Try it" setting of the studio: the page's default and the server's accepted range.

    Examples:
        >>> episodes = Limit(default=100, low=1, high=1000)
        >>> episodes.check(50, "episodes")
        50
        >>> episodes.check(0, "episodes")
        Traceback (most recent call last):
        ...
        ValueError: episodes: must be from 1 to 1000, got 0
    """

    default: int
    low: int
    high: int

    def check(self, value: Any, name: str) -> int:
        """``value`` as an int within bounds, else a ``ValueError`` naming ``name`` and the range."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{name}: expected a whole number from {self.low} to {self.high}, got {value!r}")
        if not self.low <= value <= self.high:
            raise ValueError(f"{name}: must be from {self.low} to {self.high}, got {value}")
        return value


def _file_form(predicate: Predicate) -> dict[str, Any]:
    return predicate.to_dict()


def _as_sent(subgoal: dict[str, Any], where: str) -> dict[str, Any]:
    return subgoal


@dataclass(frozen=True)
class Domain:
    """One environment, as the package's parts see it. Every field but ``name`` is optional:
    a part whose field is missing does without (no map check, no map panel, no paper column,
    not in the studio).

    Args:
        name: the subgoal files' ``domain`` value and the name sweeps record (``"four_rooms"``).
        title: a human name (the studio's menu).
        aliases: other names the domain is found by (the pick-and-place recipe's results say ``"fetch"``).
        make_env: ``make_env(num_envs)``: a batched env (batch size ``[num_envs]``).
        check_subgoal: why a predicate is not a valid subgoal on this domain's map, or ``None``;
            the subgoal loader runs it on every subgoal of a file that names the domain.
        draw_map: ``draw_map(ax, patterns, options)``, the report's map panel of each pattern.
        paper: what Okudo & Yamada (2021) report for this domain (the report's paper columns).
        geometry: the studio's map as JSON from the map's config (``""`` for a single fixed map);
            ``geometry(config)["kind"]`` picks the drawing: ``"grid"``, ``"table"`` or ``"form"``.
        maps: the studio's map names -> what the env loads (empty: a single fixed map).
        map_check: ``map_check(predicate, map_name, config)``, an extra studio check on the chosen map.
        limits: bounds of the studio's "Try it" settings ``episodes``, ``learners``, ``max_steps``.
        recipe: the recipe that trains with a saved subgoal file.
        to_page: a loaded predicate as the studio edits it; its file form by default.
        from_page: a subgoal the studio sent (without its name) as the file's predicate,
            and where it is (for messages); the identity by default.
        try_note: why "Try it" is off for this domain (it is on when ``limits`` is given).
        learner: ``learner(learners, seed, max_steps, map)``, a fresh env and the paper's online
            learner for it with its shaping settings: what the studio's "Try it" runs, on the fused
            engine (today FourRoomsEnv with SoftmaxSarsa or PinBallEnv with FourierActorCritic).
        a2c: ``a2c()``, the A2C recipe's set-up of this domain
            (:class:`~torchrl_subgoal.training.A2CDomain`).

    Examples:
        >>> from torchrl_subgoal import State
        >>> line = Domain("line", check_subgoal=lambda p: None if p.kind == "state" else "states only")
        >>> line.check_subgoal(State(3)) is None, line.describe()["name"]
        (True, 'line')
    """

    name: str
    title: str = ""
    aliases: tuple[str, ...] = ()
    make_env: Callable[[int], EnvBase] | None = None
    check_subgoal: Callable[[Predicate], str | None] | None = None
    draw_map: MapHook | None = None
    paper: PaperResults | None = None
    geometry: Callable[[str], dict[str, Any]] | None = None
    maps: Mapping[str, str] = field(default_factory=dict)
    map_check: Callable[[Predicate, str, str], str | None] | None = None
    limits: Mapping[str, Limit] = field(default_factory=dict)
    recipe: str = ""
    to_page: Callable[[Predicate], dict[str, Any]] = _file_form
    from_page: Callable[[dict[str, Any], str], dict[str, Any]] = _as_sent
    try_note: str = ""
    learner: LearnerHook | None = None
    a2c: Callable[[], A2CDomain] | None = None

    def describe(self) -> dict[str, Any]:
        """What the studio's ``/api/domains`` says about this domain."""
        return {
            "name": self.name, "title": self.title or self.name, "maps": list(self.maps), "recipe": self.recipe,
            "try_note": self.try_note,
            "limits": {k: {"default": v.default, "min": v.low, "max": v.high} for k, v in self.limits.items()},
        }

    def with_maps(self, extra: Mapping[str, str]) -> Domain:
        """This domain with more studio maps (name -> config); a name already taken is a ``ValueError``.

        Examples:
            >>> Domain("line", maps={"a": "a.cfg"}).with_maps({"b": "b.cfg"}).maps
            {'a': 'a.cfg', 'b': 'b.cfg'}
        """
        for name in extra:
            if name in self.maps:
                raise ValueError(f"{self.title or self.name} map name {name!r} is taken; rename the file")
        return dataclasses.replace(self, maps={**self.maps, **extra})


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


def names() -> list[str]:
    """The known domains' names: the built-in ones, then those registered since.

    Examples:
        >>> names()[:3]
        ['four_rooms', 'pinball', 'pick_and_place']
    """
    return [*_BUILT_IN_NAMES, *(n for n in _REGISTRY if n not in _BUILT_IN_NAMES)]


def having(field_name: str) -> list[str]:
    """The known domains whose optional field ``field_name`` is set (the built-in ones are imported now).

    Examples:
        >>> having("learner")
        ['four_rooms', 'pinball']
    """
    return [n for n in names() if getattr(find(n), field_name, None)]


def find(name: str) -> Domain | None:
    """The domain registered as ``name`` (a built-in one is imported now), or ``None``.

    Examples:
        >>> find("four_rooms").title, find("toy") is None
        ('Four rooms', True)
    """
    name = _ALIASES.get(name, name)
    if name not in _REGISTRY and name in _BUILT_IN:
        importlib.import_module(_BUILT_IN[name])
        name = _ALIASES.get(name, name)
    return _REGISTRY.get(name)


def get(name: str) -> Domain:
    """The domain registered as ``name``.

    Raises:
        UnknownDomainError: naming the known domains.

    Examples:
        >>> get("pinball").paper.window
        10
    """
    domain = find(name)
    if domain is None:
        raise UnknownDomainError(f"unknown domain {name!r}; known: {', '.join(names())}")
    return domain


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
