"""The fused engine: :func:`~torchrl_subgoal.fused.run_episodes` without per-step TorchRL calls.

Batched learning is limited by its slowest learner: every step of the batch
waits for it. In four-rooms, the slowest of 1,000 NRS learners needs about
360,000 sequential steps while the mean learner needs 60,000, and a
``step_and_maybe_reset`` call costs a fixed ~0.3-0.8 ms of TensorDict
bookkeeping whatever the batch size. This engine takes the *same objects* —
the env, its :class:`~torchrl_subgoal.SubgoalPotentialTransform` and the
learner — and runs them in one compiled loop that calls, per learner, the
same kernels in the same order with the same random numbers (each learner
draws from its own stream), so its records are identical to the TorchRL
loop's (``tests/fused/test_engine.py``) while a learner-step costs tens of
nanoseconds (four-rooms) or a few microseconds (PinBall).

One loop, :func:`torchrl_subgoal.fused._kernels.engine.fused_run`, runs every env and
learner: it calls an env's and a learner's compiled steps (``env_step``,
``env_reset``, ``learner_step``, …), which each record type (what the env's
and the learner's ``kernel_state()`` return) implements next to its own
kernels with :func:`implements`; the loop names no domain. Built in:
:class:`~torchrl_subgoal.envs.FourRoomsEnv` with
:class:`~torchrl_subgoal.fused.SoftmaxSarsa`, and
:class:`~torchrl_subgoal.envs.PinBallEnv` with
:class:`~torchrl_subgoal.fused.FourierActorCritic`; another env or learner
joins by implementing the steps (docs/adding_a_domain.md). Each runs alone
or in a ``TransformedEnv`` whose only transform is a
:class:`~torchrl_subgoal.SubgoalPotentialTransform` with a tabular or naive
potential (a subgoal series, or a lookup / region aggregation). Anything else
raises a ``TypeError`` that says so; use the TorchRL engine for it.

Learners are independent (their own random streams and tables), so a learner
that has all its episodes leaves the loop and costs nothing more: the TorchRL
loop keeps stepping it until the slowest learner is done, which in
four-rooms' NRS tail and at PinBall's 10,000-step episodes dominates the cost.
Recorded episodes are identical in both engines; a learner's final tables
(Q, θ and w, its potential) are the ones at its last recorded episode, which
equal the TorchRL loop's for the learner that finished last (and for every
learner when it runs alone). Hence a potential shared by all learners is
refused here.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any, Protocol

import numba.core.errors
import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, TransformedEnv

from torchrl_subgoal._kernels.steps import (
    env_observe,
    env_reset,
    env_scratch,
    env_shaping_observation,
    env_step,
    implements,
    learner_scratch,
    learner_step,
    missing_steps,
)
from torchrl_subgoal.fused._kernels.engine import fused_run, fused_run_uncached
from torchrl_subgoal.fused.records import EpisodeArrays, EpisodeRecords
from torchrl_subgoal.fused.shaping_record import ShapingKernelState, shaping_record
from torchrl_subgoal.potentials import TabularPotential
from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = [
    "FusedEnv",
    "FusedLearner",
    "env_observe",
    "env_reset",
    "env_scratch",
    "env_shaping_observation",
    "env_step",
    "implements",
    "learner_scratch",
    "learner_step",
    "missing_steps",
    "run_episodes_fused",
]


def _unwrap(env: EnvBase) -> tuple[EnvBase, SubgoalPotentialTransform | None]:
    """The env under the shaping transform (``None`` if bare); a clear error for any other transform."""
    if not isinstance(env, TransformedEnv):
        return env, None
    if isinstance(env.transform, SubgoalPotentialTransform):
        return env.base_env, env.transform
    raise TypeError(
        f"the fused engine runs an env alone or with one SubgoalPotentialTransform; got {env}. "
        "Use engine='torchrl' for other transforms."
    )


def _run_blocks(
    n: int,
    episodes: int,
    run_block: Callable[[EpisodeArrays], tuple[int, int]],
    progress: Callable[[int], None] | None,
) -> EpisodeRecords:
    """Call ``run_block(records)`` (one compiled block of steps) until every learner has
    ``episodes`` episodes; ``records`` are the arrays the kernels file episodes into."""
    out = EpisodeRecords(
        torch.zeros(n, episodes, dtype=torch.long), torch.zeros(n, episodes), torch.zeros(n, episodes, dtype=torch.bool)
    )
    records = EpisodeArrays.zeros(out)
    while records.episode.min() < episodes:
        taken, filed = run_block(records)
        out.env_steps += taken
        if progress is not None and filed:
            progress(filed)
    return out


def _shaping_state(shaping: SubgoalPotentialTransform | None, td: TensorDictBase, n: int) -> ShapingKernelState:
    """The transform's record (no shaping without one); a potential shared by all learners is refused."""
    if shaping is None:
        return ShapingKernelState.unshaped(n)
    pot = shaping.potential
    if isinstance(pot, TabularPotential) and not pot.batch_shape:
        raise TypeError(
            "the fused engine stops learners that have their episodes, so each needs its own "
            "potential table (a TabularPotential with the env's batch shape); use engine='torchrl'"
        )
    return shaping_record(shaping, td)


class FusedEnv(Protocol):
    """What the fused engine asks of an env: ``kernel_state(observation_key)``, a record of its state (updated in
    place) whose type implements the env's steps (:func:`implements`), and whose
    ``env_shaping_observation`` gives the entry ``observation_key`` a shaping transform reads. An optional
    ``fused_block`` attribute sets how many steps a learner makes per compiled call (default 1024).

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env: FusedEnv = FourRoomsEnv(num_envs=2)
        >>> type(env.kernel_state("cell")).__name__, env.fused_block
        ('GridKernelState', 2048)
    """

    def kernel_state(self, observation_key: Any = "observation") -> Any: ...


class FusedLearner(Protocol):
    """What the fused engine asks of a learner: ``act`` (its first actions, as in the TorchRL loop) and
    ``kernel_state()``, a record whose type implements ``learner_scratch`` and ``learner_step``
    (:func:`implements`; see docs/adding_a_domain.md).

    Examples:
        >>> from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa
        >>> agent: FusedLearner = SoftmaxSarsa(2, 5, 4, SARSA_PRESETS["released"], seed=0)
        >>> missing_steps((), agent.kernel_state())  # a record that is not an env's: its steps are missing
        ['env_scratch', 'env_observe', 'env_step', 'env_reset', 'env_shaping_observation']
    """

    def act(self, tensordict: TensorDictBase) -> TensorDictBase: ...

    def kernel_state(self) -> Any: ...


def run_episodes_fused(
    env: EnvBase,
    agent: FusedLearner,
    episodes: int,
    *,
    progress: Callable[[int], None] | None = None,
) -> EpisodeRecords:
    """Same as ``run_episodes(env, agent, episodes)`` (see the module doc), compiled.

    The env (a :class:`FusedEnv`) and the learner give their records (``kernel_state()``), whose types
    implement the engine's steps: :class:`~torchrl_subgoal.envs.FourRoomsEnv` with
    :class:`~torchrl_subgoal.fused.SoftmaxSarsa`, :class:`~torchrl_subgoal.envs.PinBallEnv` with
    :class:`~torchrl_subgoal.fused.FourierActorCritic`, or any env and learner whose records do
    (docs/adding_a_domain.md). A pair that does not fit is a ``TypeError`` that says why.

    Args:
        env: the env (its batch is the learners), alone or in a ``TransformedEnv`` with one
            :class:`~torchrl_subgoal.SubgoalPotentialTransform`.
        agent: the learner, one per env of the batch.
        episodes: episodes every learner runs.
        progress: called with the number of episodes filed after each compiled block.

    Examples:
        >>> from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env = FourRoomsEnv(num_envs=8)
        >>> agent = SoftmaxSarsa(8, env.num_states, 4, SARSA_PRESETS["released"], seed=0)
        >>> run_episodes_fused(env, agent, 3).steps.shape
        torch.Size([8, 3])
    """
    base, shaping = _unwrap(env)
    if base.device is not None and base.device.type != "cpu":
        raise TypeError("the fused engine runs on the CPU")
    if not hasattr(base, "kernel_state") or not hasattr(agent, "kernel_state"):
        raise TypeError(
            f"the fused engine runs an env and a learner whose kernel_state() records implement its "
            f"steps (docs/adding_a_domain.md); {type(base).__name__} with {type(agent).__name__} "
            "do not: use engine='torchrl'"
        )
    td = agent.act(env.reset())  # the same start as the TorchRL loop, tables compiled
    n = max(1, env.batch_size.numel())
    action = td.get("action").reshape(-1).numpy().copy()
    state = _shaping_state(shaping, td, n)
    record = base.kernel_state("observation" if shaping is None else shaping.observation_key)
    learner = agent.kernel_state()
    missing = missing_steps(record, learner)
    if missing:
        raise TypeError(
            f"{type(record).__name__} and {type(learner).__name__} do not implement the fused engine's "
            f"{', '.join(missing)} (register them with torchrl_subgoal.fused.engine.implements; "
            "docs/adding_a_domain.md)"
        )
    packaged = all(type(r).__module__.startswith("torchrl_subgoal.") for r in (record, learner))
    loop = fused_run if packaged else fused_run_uncached  # see fused_run_uncached
    block = getattr(base, "fused_block", 1024)

    def run_block(records: EpisodeArrays) -> tuple[int, int]:
        try:
            return loop(record, state, learner, action, block, records)
        except numba.core.errors.TypingError as error:
            plain = re.sub(r"\x1b\[[0-9;]*m", "", str(error))  # numba highlights its message
            said = [line for line in plain.splitlines() if line.strip() and "Failed in" not in line]
            raise TypeError(
                f"the fused loop does not compile for {type(record).__name__} with "
                f"{type(learner).__name__} (does what env_step returns fit what learner_step reads?): "
                f"{said[0] if said else error}"
            ) from None

    return _run_blocks(n, episodes, run_block, progress)
