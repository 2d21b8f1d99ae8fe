"""The domains the studio draws: their maps as JSON, extra map checks and "Try it" bounds.

A :class:`Domain` is everything the studio needs to edit one environment's
subgoals; the page is driven by what it serves (``geometry()["kind"]`` picks
the drawing: ``"grid"`` for cells, ``"table"`` for circles on a continuous
map). The maps come from the environments' own definitions
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

from torchrl_subgoal.envs import four_rooms
from torchrl_subgoal.envs import pinball as pinball_env
from torchrl_subgoal.envs.pinball import PinBallConfig
from torchrl_subgoal.subgoals import Cell, Circle, Predicate, State

__all__ = ["Domain", "Limit", "default_domains"]


@dataclass(frozen=True)
class Limit:
    """Bounds of one "Try it" setting: the page's default and the server's accepted range."""

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
        drawable: a predicate as the page draws it (four-rooms: a state number
            becomes its cell); the identity by default.
    """

    name: str
    title: str
    check_subgoal: Callable[[Predicate], str | None]
    geometry: Callable[[str], dict[str, Any]]
    maps: Mapping[str, str] = field(default_factory=dict)
    map_check: Callable[[Predicate, str], str | None] | None = None
    limits: Mapping[str, Limit] = field(default_factory=dict)
    recipe: str = ""
    drawable: Callable[[Predicate], Predicate] = lambda predicate: predicate

    def describe(self) -> dict[str, Any]:
        """What ``/api/domains`` says about this domain."""
        return {
            "name": self.name, "title": self.title, "maps": list(self.maps), "recipe": self.recipe,
            "limits": {k: {"default": v.default, "min": v.low, "max": v.high} for k, v in self.limits.items()},
        }


def _four_rooms_geometry(map_name: str) -> dict[str, Any]:
    return {
        "kind": "grid", "rows": four_rooms.LAYOUT.splitlines(), "wall": "w", "start": list(four_rooms.START),
        "goal": list(four_rooms.GOAL), "hallways": [list(h) for h in four_rooms.HALLWAYS],
    }


def _cell_of_state(predicate: Predicate) -> Predicate:
    if isinstance(predicate, State):
        return Cell(*four_rooms.free_cells()[predicate.state])
    return predicate


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
            if pinball_env._point_in_polygon((x, y), polygon):
                return (f"centre ({x:g}, {y:g}) lies inside obstacle {i + 1} of the {map_name!r} map; "
                        "move it to where the ball can go")
        return None

    return check


def default_domains(pinball_maps: Mapping[str, str | Path] | None = None) -> dict[str, Domain]:
    """Four-rooms and PinBall (maps ``simple``, ``hard`` and ``pinball_maps``: name -> file).

    Examples:
        >>> domains = default_domains()
        >>> sorted(domains), list(domains["pinball"].maps)
        (['four_rooms', 'pinball'], ['simple', 'hard'])
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
            recipe="recipes/four_rooms.py", drawable=_cell_of_state,
        ),
        "pinball": Domain(
            "pinball", "PinBall", pinball_env.check_subgoal, lambda m: _pinball_geometry(maps[m]), maps,
            map_check=_pinball_map_check(maps),
            limits={"episodes": Limit(30, 1, 100), "learners": Limit(5, 1, 10),
                    "max_steps": Limit(10_000, 100, 10_000)},
            recipe="recipes/pinball.py",
        ),
    }
