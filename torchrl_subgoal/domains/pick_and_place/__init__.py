"""The pick-and-place domain plugin: env, subgoal check, and each layer's part (paper numbers, studio form).

Everything the package knows about pick-and-place beyond the env itself, in one
place; :mod:`torchrl_subgoal.domains` imports this module the first time
``"pick_and_place"`` (or ``"fetch"``, what its recipe's results record) is looked
up. Nothing here needs MuJoCo until an env is made: the env factory raises
:class:`~torchrl_subgoal.envs.fetch.FetchUnavailableError`, one line naming the
install command, when the ``fetch`` extra is missing.
"""

from __future__ import annotations

from torchrl.envs import EnvBase

from torchrl_subgoal import domains
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.experiments.paper import PaperResults
from torchrl_subgoal.studio.domains import BoxForm, StudioDomain
from torchrl_subgoal.subgoals import Box, Predicate

__all__ = ["DOMAIN", "FORM", "PAPER", "STUDIO", "check_subgoal", "fetch_env"]


def check_subgoal(predicate: Predicate) -> str | None:
    """Why ``predicate`` is not a valid pick-and-place subgoal, or ``None``.

    A pick-and-place subgoal is a box over entries of the 25-d observation.
    Used by subgoal files that declare ``domain: pick_and_place``.

    Examples:
        >>> check_subgoal(Box((0.0,), (0.01,), (30,)))
        'box entries [30] lie outside the 25-d observation (entries 0 to 24)'
    """
    if not isinstance(predicate, Box):
        return f"pick-and-place subgoals are boxes over observation entries, not {predicate.kind}"
    outside = [d for d in predicate.box_dims if d >= fetch.OBSERVATION_SIZE]
    if outside:
        return (
            f"box entries {outside} lie outside the {fetch.OBSERVATION_SIZE}-d observation "
            f"(entries 0 to {fetch.OBSERVATION_SIZE - 1})"
        )
    return None


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


#: The form: boxes over the observation's named components, a new one over the relative position.
FORM = BoxForm(fetch.COMPONENTS, fetch.OBSERVATION_SIZE, fetch.SUBGOAL_MARGIN, ticked=("object_relative_position",))


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
    FORM.geometry,
    recipe="torchrl-subgoal reproduce pick-and-place",
    to_page=FORM.to_page,
    from_page=FORM.from_page,
    try_note=TRY_NOTE,
    position=2,
)

DOMAIN = domains.register(
    domains.Domain(
        "pick_and_place",
        "Pick and place",
        aliases=("fetch",),
        make_env=fetch_env,
        check_subgoal=check_subgoal,
        parts=(PAPER, STUDIO),
    )
)
