"""The domains the studio draws: their maps as JSON, extra map checks and "Try it" bounds.

A :class:`Domain` is everything the studio needs to edit one environment's
subgoals; the page is driven by what it serves (``geometry()["kind"]`` picks
the drawing: ``"grid"`` for cells, ``"table"`` for circles on a continuous
map, ``"form"`` for boxes over named observation components). The maps come from the environments' own definitions
(:mod:`torchrl_subgoal.envs.four_rooms`' ``LAYOUT``, PinBall's configuration
loader), never a copy. Adding a domain is one more :class:`Domain` in
:func:`default_domains`, one builder in :mod:`torchrl_subgoal.studio.training`
and, if it needs a new kind of drawing, one more case in ``studio.js``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from torchrl_subgoal.envs import fetch, four_rooms
from torchrl_subgoal.envs import pinball as pinball_env
from torchrl_subgoal.envs.pinball import PinBallConfig
from torchrl_subgoal.subgoals import Box, Cell, Circle, Predicate, State

__all__ = ["Domain", "FormError", "Limit", "default_domains"]


@dataclass(frozen=True)
class Limit:
    """Bounds of one "Try it" setting: the page's default and the server's accepted range.

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
class Domain:
    """One environment the studio edits subgoals for.

    Args:
        name: the subgoal files' ``domain`` value (``"four_rooms"``).
        title: shown on the page.
        check_subgoal: the subgoal loader's own map check (``None`` = fits);
            also decides which domain a loaded file belongs to.
        geometry: map name -> the JSON the page draws.
        maps: map name -> what the env loads (empty: a single fixed map).
        map_check: an extra check of one subgoal on the chosen map, or ``None``.
        limits: bounds of the "Try it" settings ``episodes``, ``learners``, ``max_steps``.
        recipe: the recipe that trains with a saved file.
        to_page: a loaded predicate as the page edits it (four-rooms: a state
            number becomes its cell); its file form by default.
        from_page: a subgoal the page sent (without its name) as the file's
            predicate, and where it is (for messages); the identity by default.
        try_note: why "Try it" is off for this domain (it is on when ``limits`` is given).

    Examples:
        >>> from torchrl_subgoal.envs.four_rooms import check_subgoal
        >>> domain = Domain("four_rooms", "Four rooms", check_subgoal, lambda map_name: {})
        >>> domain.describe()["name"], domain.check_subgoal(Cell(0, 0))
        ('four_rooms', '(0, 0) is a wall')
    """

    name: str
    title: str
    check_subgoal: Callable[[Predicate], str | None]
    geometry: Callable[[str], dict[str, Any]]
    maps: Mapping[str, str] = field(default_factory=dict)
    map_check: Callable[[Predicate, str], str | None] | None = None
    limits: Mapping[str, Limit] = field(default_factory=dict)
    recipe: str = ""
    to_page: Callable[[Predicate], dict[str, Any]] = lambda predicate: predicate.to_dict()
    from_page: Callable[[dict[str, Any], str], dict[str, Any]] = lambda subgoal, where: subgoal
    try_note: str = ""

    def describe(self) -> dict[str, Any]:
        """What ``/api/domains`` says about this domain."""
        return {
            "name": self.name, "title": self.title, "maps": list(self.maps), "recipe": self.recipe,
            "try_note": self.try_note,
            "limits": {k: {"default": v.default, "min": v.low, "max": v.high} for k, v in self.limits.items()},
        }


def _four_rooms_geometry(map_name: str) -> dict[str, Any]:
    return {
        "kind": "grid", "rows": four_rooms.LAYOUT.splitlines(), "wall": "w", "start": list(four_rooms.START),
        "goal": list(four_rooms.GOAL), "hallways": [list(h) for h in four_rooms.HALLWAYS],
    }


def _cell_of_state(predicate: Predicate) -> dict[str, Any]:
    if isinstance(predicate, State):
        return Cell(*four_rooms.free_cells()[predicate.state]).to_dict()
    return predicate.to_dict()


class FormError(ValueError):
    """A subgoal the page sent (or a file holds) that the form cannot express; the message says where.

    Examples:
        >>> _box_from_page({"box": {"components": []}}, "patterns.p.subgoals[0]")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.domains.FormError: patterns.p.subgoals[0].box.components: expected a non-empty list of component names, got []
    """


def _fetch_geometry(map_name: str) -> dict[str, Any]:
    return {
        "kind": "form", "observation_size": fetch.OBSERVATION_SIZE, "default_margin": fetch.SUBGOAL_MARGIN,
        "components": [{"name": n, "start": s.start, "size": s.stop - s.start} for n, s in fetch.COMPONENTS.items()],
    }


def _box_to_page(predicate: Predicate) -> dict[str, Any]:
    """A box as ``{"box": {"components", "centre", "margin"}}`` (a single margin when all are equal)."""
    body = predicate.to_dict()
    if not isinstance(predicate, Box):
        return body
    names = fetch.components_of(predicate.box_dims)
    if names is None:
        raise FormError(f"box entries {list(predicate.box_dims)} are not whole observation components "
                        f"({', '.join(fetch.COMPONENTS)}); the form edits whole components, edit this file by hand")
    box = body["box"]
    return {"box": {"components": list(names), "centre": box["centre"], "margin": box["margin"]}}


def _box_from_page(subgoal: dict[str, Any], where: str) -> dict[str, Any]:
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
        dims = fetch.component_dims(*names)
    except KeyError as exc:
        raise FormError(f"{where}.box.components: {exc.args[0]}") from None
    centre = box.get("centre")
    if isinstance(centre, list) and len(centre) != len(dims):
        raise FormError(f"{where}.box.centre: {len(centre)} values, but {', '.join(names)} "
                        f"{'has' if len(names) == 1 else 'have'} {len(dims)} coordinates; give one per coordinate")
    rest = {k: v for k, v in box.items() if k != "components"}
    return {**subgoal, "box": {**rest, "dims": list(dims)}}


@functools.lru_cache(maxsize=32)
def _load_map(config: str) -> PinBallConfig:
    return PinBallConfig.load(config)


def _pinball_geometry(config: str) -> dict[str, Any]:
    cfg = _load_map(config)
    return {
        "kind": "table", "ball_radius": cfg.ball_radius, "target": list(cfg.target), "start": list(cfg.start),
        "polygons": [[list(v) for v in poly] for poly in cfg.polygons],
        "default_radius": cfg.target[2],  # the target's radius, as the paper's participants' circles
    }


def _pinball_map_check(maps: Mapping[str, str]) -> Callable[[Predicate, str], str | None]:
    def check(predicate: Predicate, map_name: str) -> str | None:
        if not isinstance(predicate, Circle):
            return None
        cfg = _load_map(maps[map_name])
        x, y = predicate.centre[:2]
        for i, polygon in enumerate(cfg.polygons):
            if pinball_env.point_in_polygon((x, y), polygon):
                return (f"centre ({x:g}, {y:g}) lies inside obstacle {i + 1} of the {map_name!r} map; "
                        "move it to where the ball can go")
        return None

    return check


TRY_NOTE_FETCH = (
    "Not offered for pick-and-place: one epoch of DDPG in MuJoCo took about 10 minutes on a shared "
    "2-core machine (docs/pick_and_place.md), far too slow for a click. Save the file and run the "
    "recipe command shown under File."
)


def default_domains(pinball_maps: Mapping[str, str | Path] | None = None) -> dict[str, Domain]:
    """Four-rooms, PinBall (maps ``simple``, ``hard`` and ``pinball_maps``: name -> file), pick-and-place.

    Pick-and-place needs no MuJoCo here: its form is built from
    :data:`torchrl_subgoal.envs.fetch.COMPONENTS`.

    Examples:
        >>> domains = default_domains()
        >>> sorted(domains), list(domains["pinball"].maps)
        (['four_rooms', 'pick_and_place', 'pinball'], ['simple', 'hard'])
        >>> domains["four_rooms"].geometry("")["rows"][0]
        'wwwwwwwwwwwww'
    """
    maps: dict[str, str] = {"simple": "simple", "hard": "hard"}
    for name, path in (pinball_maps or {}).items():
        if name in maps:
            raise ValueError(f"PinBall map name {name!r} is taken; rename the file")
        PinBallConfig.load(path)  # a bad file fails at start-up, with its line
        maps[name] = str(path)
    return {
        "four_rooms": Domain(
            "four_rooms", "Four rooms", four_rooms.check_subgoal, _four_rooms_geometry,
            limits={"episodes": Limit(300, 1, 2000), "learners": Limit(20, 1, 200),
                    "max_steps": Limit(1000, 50, 1000)},
            recipe="recipes/four_rooms.py", to_page=_cell_of_state,
        ),
        "pinball": Domain(
            "pinball", "PinBall", pinball_env.check_subgoal, lambda m: _pinball_geometry(maps[m]), maps,
            map_check=_pinball_map_check(maps),
            limits={"episodes": Limit(30, 1, 100), "learners": Limit(5, 1, 10),
                    "max_steps": Limit(10_000, 100, 10_000)},
            recipe="recipes/pinball.py",
        ),
        "pick_and_place": Domain(
            "pick_and_place", "Pick and place", fetch.check_subgoal, _fetch_geometry,
            recipe="recipes/pick_and_place.py", to_page=_box_to_page, from_page=_box_from_page,
            try_note=TRY_NOTE_FETCH,
        ),
    }
