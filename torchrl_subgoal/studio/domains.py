"""The domains the studio draws: every registered domain that has a studio map.

The studio's view of a domain is the :class:`torchrl_subgoal.domains.Domain` it
registered (its ``geometry``, ``maps``, ``map_check``, ``limits``, ...): the
page is driven by what it serves (``geometry(config)["kind"]`` picks the
drawing: ``"grid"`` for cells, ``"table"`` for circles on a continuous map,
``"form"`` for boxes over named observation components). Adding a domain to the
studio is giving its registration a ``geometry`` of one of those kinds
(docs/adding_a_domain.md); "Try it" also needs a builder in
:mod:`torchrl_subgoal.studio.training`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from torchrl_subgoal import domains
from torchrl_subgoal.domains import Domain, FormError, Limit

__all__ = ["Domain", "FormError", "Limit", "default_domains"]


def default_domains(pinball_maps: Mapping[str, str | Path] | None = None) -> dict[str, Domain]:
    """Every registered domain with a studio map, PinBall with the maps ``simple``, ``hard`` and
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
    found = {name: domains.get(name) for name in domains.names()}
    drawn = {name: domain for name, domain in found.items() if domain.geometry is not None}
    extra = {name: str(path) for name, path in (pinball_maps or {}).items()}
    if extra:
        pinball = drawn["pinball"].with_maps(extra)
        for config in extra.values():
            pinball.geometry(config)  # type: ignore[misc]  # loads the file: a bad one fails at start-up
        drawn["pinball"] = pinball
    return drawn
