"""The domains the studio draws: every registered domain with a :class:`StudioDomain` part.

A domain's studio part says how the page draws its map (``geometry(config)["kind"]``:
``"grid"`` for cells, ``"table"`` for circles on a continuous map, ``"form"`` for
boxes over named observation components), which maps it offers, the bounds of
"Try it" and the paper's learner it runs (docs/adding_a_domain.md). The studio
sees each domain through a :class:`StudioDomain` carrying the registration's
name, title and subgoal check beside those fields.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from torchrl_subgoal import domains

if TYPE_CHECKING:
    from torchrl.envs import EnvBase

    from torchrl_subgoal.agents.loop import OnlineAgent
    from torchrl_subgoal.subgoals import Predicate

__all__ = ["Domain", "FormError", "Limit", "StudioDomain", "default_domains", "studio_domain"]

#: ``learner(learners, seed, max_steps, map)``: a fresh batched env (``max_steps`` and ``map`` ``None``:
#: the domain's own) and the paper's online learner for it, with the settings of its shaping
#: transform (``gamma``, ``value_lr``, ``observation_key``).
LearnerHook = Callable[[int, int, int | None, str | None], tuple["EnvBase", "OnlineAgent", Mapping[str, Any]]]


class FormError(ValueError):
    """A subgoal the studio's page sent (or a file holds) that the domain's form cannot express;
    the message says where.

    Examples:
        >>> raise FormError("patterns.p.subgoals[0].box.components: expected a non-empty list")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.domains.FormError: patterns.p.subgoals[0].box.components: expected a non-empty list
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
class StudioDomain:
    """What the studio needs of a domain: the part of its registration that puts it in the studio.

    A plugin registers it without ``name``, ``title`` and ``check_subgoal``; :func:`default_domains`
    fills those from the registration.

    Args:
        geometry: the map as JSON from the map's config (``""`` for a single fixed map);
            ``geometry(config)["kind"]`` picks the drawing: ``"grid"``, ``"table"`` or ``"form"``.
        maps: the studio's map names -> what the env loads (empty: a single fixed map).
        map_check: ``map_check(predicate, map_name, config)``, an extra check on the chosen map.
        limits: bounds of the "Try it" settings ``episodes``, ``learners``, ``max_steps`` (none: no "Try it").
        recipe: the recipe that trains with a saved subgoal file.
        to_page: a loaded predicate as the studio edits it; its file form by default.
        from_page: a subgoal the studio sent (without its name) as the file's predicate, and where it is
            (for messages); the identity by default.
        try_note: why "Try it" is off for this domain.
        learner: ``learner(learners, seed, max_steps, map)``, a fresh env and the paper's online learner
            for it with its shaping settings: what "Try it" runs, on the fused engine.
        position: where the studio's menu lists the domain (lower first; ties in the registry's order).
        name: the registration's name.
        title: the registration's title.
        check_subgoal: the registration's subgoal check.

    Examples:
        >>> line = StudioDomain(geometry=lambda config: {"kind": "grid"}, name="line")
        >>> line.describe()["name"], line.geometry("")["kind"]
        ('line', 'grid')
    """

    geometry: Callable[[str], dict[str, Any]]
    maps: Mapping[str, str] = field(default_factory=dict)
    map_check: Callable[[Predicate, str, str], str | None] | None = None
    limits: Mapping[str, Limit] = field(default_factory=dict)
    recipe: str = ""
    to_page: Callable[[Predicate], dict[str, Any]] = _file_form
    from_page: Callable[[dict[str, Any], str], dict[str, Any]] = _as_sent
    try_note: str = ""
    learner: LearnerHook | None = None
    position: int = 100
    name: str = ""
    title: str = ""
    check_subgoal: Callable[[Predicate], str | None] | None = None

    def describe(self) -> dict[str, Any]:
        """What the studio's ``/api/domains`` says about this domain."""
        return {
            "name": self.name,
            "title": self.title or self.name,
            "maps": list(self.maps),
            "recipe": self.recipe,
            "try_note": self.try_note,
            "limits": {k: {"default": v.default, "min": v.low, "max": v.high} for k, v in self.limits.items()},
        }

    def with_maps(self, extra: Mapping[str, str]) -> StudioDomain:
        """This domain with more studio maps (name -> config); a name already taken is a ``ValueError``.

        Examples:
            >>> line = StudioDomain(geometry=lambda config: {}, maps={"a": "a.cfg"})
            >>> line.with_maps({"b": "b.cfg"}).maps
            {'a': 'a.cfg', 'b': 'b.cfg'}
        """
        for name in extra:
            if name in self.maps:
                raise ValueError(f"{self.title or self.name} map name {name!r} is taken; rename the file")
        return dataclasses.replace(self, maps={**self.maps, **extra})


#: the studio's view of a domain (what its server and documents read)
Domain = StudioDomain


def studio_domain(name: str) -> StudioDomain | None:
    """The studio's view of the registered domain ``name`` (``None``: it has no studio part).

    Examples:
        >>> studio_domain("four_rooms").title
        'Four rooms'
    """
    registered = domains.find(name)
    studio = registered.part(StudioDomain) if registered is not None else None
    if registered is None or studio is None:
        return None
    return dataclasses.replace(
        studio, name=registered.name, title=registered.title, check_subgoal=registered.check_subgoal
    )


def default_domains(pinball_maps: Mapping[str, str | Path] | None = None) -> dict[str, StudioDomain]:
    """Every registered domain with a studio part, PinBall with the maps ``simple``, ``hard`` and
    ``pinball_maps`` (name -> file; a bad file fails here, with its line).

    Pick-and-place needs no MuJoCo here: its form is built from
    :data:`torchrl_subgoal.envs.fetch.COMPONENTS`.

    Examples:
        >>> studio_domains = default_domains()
        >>> sorted(studio_domains), list(studio_domains["pinball"].maps)
        (['four_rooms', 'pick_and_place', 'pinball'], ['simple', 'hard'])
        >>> studio_domains["four_rooms"].geometry("")["rows"][0]
        'wwwwwwwwwwwww'
    """
    views = [view for name in domains.names() if (view := studio_domain(name)) is not None]
    drawn = {view.name: view for view in sorted(views, key=lambda view: view.position)}
    extra = {name: str(path) for name, path in (pinball_maps or {}).items()}
    if extra:
        pinball = drawn["pinball"].with_maps(extra)
        for config in extra.values():
            pinball.geometry(config)  # loads the file: a bad one fails at start-up
        drawn["pinball"] = pinball
    return drawn
