"""The pick-and-place domain plugin: env, subgoal check, and each layer's part (paper numbers, studio form).

Everything the package knows about pick-and-place beyond the env itself, in one
place; :mod:`torchrl_subgoal.domains` imports this module the first time
``"pick_and_place"`` (or ``"fetch"``, what its recipe's results record) is looked
up. Nothing here needs MuJoCo until an env is made: the env factory raises
:class:`~torchrl_subgoal.envs.fetch.FetchUnavailableError`, one line naming the
install command, when the ``fetch`` extra is missing.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from torchrl.envs import EnvBase

from torchrl_subgoal import domains
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.experiments.paper import PaperResults
from torchrl_subgoal.studio.domains import FormError, StudioDomain
from torchrl_subgoal.subgoals import Box, Predicate

__all__ = ["DOMAIN", "PAPER", "STUDIO", "fetch_env"]


def fetch_env(num_envs: int) -> EnvBase:
    """``num_envs`` single-goal FetchPickAndPlace envs (goal seed 0) as one batched env.

    Raises:
        FetchUnavailableError: MuJoCo or gymnasium-robotics is missing; the message names the install command.

    Examples:
        >>> fetch_env(2).batch_size  # doctest: +SKIP
        torch.Size([2])
    """
    fetch.require_fetch()  # the one-line error naming the install command, before any env is made
    return fetch.make_fetch_envs(0, num_envs)


def _geometry(config: str) -> dict[str, Any]:
    return {
        "kind": "form",
        "observation_size": fetch.OBSERVATION_SIZE,
        "default_margin": fetch.SUBGOAL_MARGIN,
        "components": [{"name": n, "start": s.start, "size": s.stop - s.start} for n, s in fetch.COMPONENTS.items()],
    }


def _box_to_page(predicate: Predicate) -> dict[str, Any]:
    """A box as ``{"box": {"components", "centre", "margin"}}`` (a single margin when all are equal)."""
    body = predicate.to_dict()
    if not isinstance(predicate, Box):
        return body
    names = fetch.components_of(predicate.box_dims)
    if names is None:
        raise FormError(
            f"box entries {list(predicate.box_dims)} are not whole observation components "
            f"({', '.join(fetch.COMPONENTS)}); the form edits whole components, edit this file by hand"
        )
    box = body["box"]
    return {"box": {"components": list(names), "centre": box["centre"], "margin": box["margin"]}}


def _box_from_page(subgoal: dict[str, Any], where: str) -> dict[str, Any]:
    """``{"box": {"components": [...], ...}}`` as the file's ``{"box": {"dims": [...], ...}}``.

    Examples:
        >>> _box_from_page({"box": {"components": []}}, "patterns.p.subgoals[0]")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.domains.FormError: patterns.p.subgoals[0].box.components: expected a non-empty list ...
    """
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
        raise FormError(
            f"{where}.box.centre: {len(centre)} values, but {', '.join(names)} "
            f"{'has' if len(names) == 1 else 'have'} {len(dims)} coordinates; give one per coordinate"
        )
    rest = {k: v for k, v in box.items() if k != "components"}
    return {**subgoal, "box": {**rest, "dims": list(dims)}}


TRY_NOTE = (
    "Not offered for pick-and-place: one epoch of DDPG in MuJoCo took about 10 minutes on a shared "
    "2-core machine (docs/pick_and_place.md), far too slow for a click. Save the file and run the "
    "recipe command shown under File."
)

PAPER = PaperResults(
    domain="fetch",
    metric="success",
    window=1,
    time_to_threshold={},
    asymptotic={"HRS": 0.67, "DDPG": 0.63, "NRS": 0.49, "RRS": 0.43},
    asymptotic_window=(190, 200),
    learnings=5,
    notes=("Success rate 0.6 reached 30 epochs earlier with HRS than with DDPG.",),
)

STUDIO = StudioDomain(
    _geometry,
    recipe="recipes/pick_and_place.py",
    to_page=_box_to_page,
    from_page=_box_from_page,
    try_note=TRY_NOTE,
    position=2,
)

DOMAIN = domains.register(
    domains.Domain(
        "pick_and_place",
        "Pick and place",
        aliases=("fetch",),
        make_env=fetch_env,
        check_subgoal=fetch.check_subgoal,
        parts=(PAPER, STUDIO),
    )
)
