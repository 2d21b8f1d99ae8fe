"""The domains the studio draws: every registered domain with a :class:`StudioDomain` part.

A domain's studio part says how the page draws its map (``geometry(config)["kind"]``:
``"grid"`` for cells, ``"table"`` for circles on a continuous plane, ``"form"`` for
boxes over named observation components, see :class:`BoxForm`), which maps it offers, the bounds of
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

from torchrl_subgoal import registry
from torchrl_subgoal.subgoals import Box

if TYPE_CHECKING:
    from torchrl.envs import EnvBase

    from torchrl_subgoal.fused.loop import OnlineAgent
    from torchrl_subgoal.subgoals import Predicate

__all__ = ["BoxForm", "Domain", "FormError", "Limit", "StudioDomain", "default_domains", "studio_domain"]

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


@dataclass(frozen=True)
class BoxForm:
    """The ``"form"`` kind: box subgoals over named observation components, edited by name.

    The page ticks components and types a target per coordinate; the file holds the
    entries (``dims``). Give its :meth:`geometry`, :meth:`to_page` and :meth:`from_page`
    to the domain's :class:`StudioDomain`.

    Args:
        components: name -> the observation entries it covers, in the form's order.
        observation_size: entries in the observation.
        default_margin: the margin of a new box.
        ticked: the components a new box covers until others are ticked.
        ranges: name -> the ``(low, high)`` of its values, shown beside the name (optional).

    Examples:
        >>> form = BoxForm({"position": slice(0, 1), "velocity": slice(1, 2)}, 2, 0.05, ticked=("position",))
        >>> form.from_page({"box": {"components": ["velocity"], "centre": [0.01], "margin": 0.01}}, "p")
        {'box': {'centre': [0.01], 'margin': 0.01, 'dims': [1]}}
        >>> form.to_page(Box((0.01,), (0.01,), (1,)))
        {'box': {'components': ['velocity'], 'centre': [0.01], 'margin': 0.01}}
        >>> form.from_page({"box": {"components": []}}, "patterns.p.subgoals[0]")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.domains.FormError: patterns.p.subgoals[0].box.components: expected a non-empty list ...
    """

    components: Mapping[str, slice]
    observation_size: int
    default_margin: float
    ticked: tuple[str, ...] = ()
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def geometry(self, config: str) -> dict[str, Any]:
        """The form as the page draws it (``config`` is unused: a form has one map)."""
        return {
            "kind": "form",
            "observation_size": self.observation_size,
            "default_margin": self.default_margin,
            "ticked": list(self.ticked),
            "components": [
                {"name": n, "start": s.start, "size": s.stop - s.start}
                | ({"range": list(self.ranges[n])} if n in self.ranges else {})
                for n, s in self.components.items()
            ],
        }

    def dims(self, names: list[str]) -> tuple[int, ...]:
        """The observation entries of the named components, in order (``KeyError``: an unknown name)."""
        unknown = [n for n in names if n not in self.components]
        if unknown:
            raise KeyError(f"unknown observation component(s) {unknown}; known: {list(self.components)}")
        return tuple(d for n in names for d in range(self.components[n].start, self.components[n].stop))

    def names(self, dims: tuple[int, ...]) -> list[str] | None:
        """The whole components whose entries, in order, are ``dims`` (``None``: there are none such)."""
        names: list[str] = []
        i = 0
        while i < len(dims):
            match = next(
                (
                    n
                    for n, s in self.components.items()
                    if tuple(dims[i : i + s.stop - s.start]) == tuple(range(s.start, s.stop))
                ),
                None,
            )
            if match is None:
                return None
            names.append(match)
            i += self.components[match].stop - self.components[match].start
        return names

    def to_page(self, predicate: Predicate) -> dict[str, Any]:
        """A box as ``{"box": {"components", "centre", "margin"}}`` (a single margin when all are equal)."""
        body = predicate.to_dict()
        if not isinstance(predicate, Box):
            return body
        names = self.names(tuple(predicate.box_dims))
        if names is None:
            raise FormError(
                f"box entries {list(predicate.box_dims)} are not whole observation components "
                f"({', '.join(self.components)}); the form edits whole components, edit this file by hand"
            )
        box = body["box"]
        return {"box": {"components": names, "centre": box["centre"], "margin": box["margin"]}}

    def from_page(self, subgoal: dict[str, Any], where: str) -> dict[str, Any]:
        """``{"box": {"components": [...], ...}}`` as the file's ``{"box": {"dims": [...], ...}}``."""
        box = subgoal.get("box")
        if not isinstance(box, Mapping) or "components" not in box:
            return subgoal
        names = box["components"]
        if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
            raise FormError(f"{where}.box.components: expected a non-empty list of component names, got {names!r}")
        if "dims" in box or "slice" in box:
            raise FormError(f"{where}.box: give 'components' or 'dims'/'slice', not both")
        try:
            dims = self.dims(names)
        except KeyError as exc:
            raise FormError(f"{where}.box.components: {exc.args[0]}") from None
        centre = box.get("centre")
        if isinstance(centre, list) and len(centre) != len(dims):
            raise FormError(
                f"{where}.box.centre: {len(centre)} values, but {', '.join(names)} "
                f"{'has' if len(names) == 1 else 'have'} {len(dims)} coordinates; give one per coordinate"
            )
        rest = {k: v for k, v in box.items() if k != "components"}
        return {**subgoal, "box": {**rest, "dims": list(dims)}}


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
        recipe: the recipe that trains with a saved subgoal file, with any options it needs before
            ``--subgoals FILE`` (``"torchrl-subgoal train --algo ppo --domain NAME"``).
        to_page: a loaded predicate as the studio edits it; its file form by default.
        from_page: a subgoal the studio sent (without its name) as the file's predicate, and where it is
            (for messages); the identity by default.
        try_note: why "Try it" is off for this domain.
        pattern_names: the names a pattern may have, when the recipe runs each pattern on the task it is
            named after (empty: any name); the page names new patterns with them.
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
    pattern_names: tuple[str, ...] = ()
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
            "pattern_names": list(self.pattern_names),
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
    registered = registry.find(name)
    studio = registered.part(StudioDomain) if registered is not None else None
    if registered is None or studio is None:
        return None
    return dataclasses.replace(
        studio, name=registered.name, title=registered.title, check_subgoal=registered.check_subgoal
    )


def default_domains(pinball_maps: Mapping[str, str | Path] | None = None) -> dict[str, StudioDomain]:
    """Every registered domain with a studio part, PinBall with the maps ``simple``, ``hard`` and
    ``pinball_maps`` (name -> file; a bad file fails here, with its line).

    No domain needs its simulator here: pick-and-place's form is built from
    :data:`torchrl_subgoal.envs.fetch.COMPONENTS`, PointMaze's walls from
    :data:`torchrl_subgoal.envs.point_maze.MAZES`.

    Examples:
        >>> studio_domains = default_domains()
        >>> list(studio_domains)
        ['four_rooms', 'pinball', 'pick_and_place', 'point_maze_umaze', 'point_maze_medium', 'mountain_car']
        >>> list(studio_domains["pinball"].maps)
        ['simple', 'hard']
        >>> studio_domains["four_rooms"].geometry("")["rows"][0]
        'wwwwwwwwwwwww'
    """
    views = [view for name in registry.names() if (view := studio_domain(name)) is not None]
    drawn = {view.name: view for view in sorted(views, key=lambda view: view.position)}
    extra = {name: str(path) for name, path in (pinball_maps or {}).items()}
    if extra:
        pinball = drawn["pinball"].with_maps(extra)
        for config in extra.values():
            pinball.geometry(config)  # loads the file: a bad one fails at start-up
        drawn["pinball"] = pinball
    return drawn
