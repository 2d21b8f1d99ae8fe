"""What a building block returns: each learner's curve and its trained modules; saving, loading, evaluating.

Every ``train_<algo>`` returns a :class:`Trained`: the learners' curves, their
networks (stacked over the learners: actor, critic or Q-network, the DDPG
agent's normaliser), the shaping potential (one table per learner) and how to
get one learner's greedy policy (:meth:`Trained.policy`). :meth:`Trained.save`
writes them as state dicts with the settings; :func:`~torchrl_subgoal.training.load_trained` rebuilds
them in another process from the same env factory. :func:`evaluate` runs a
policy's greedy episodes and reports their returns, lengths and success.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.envs import EnvBase, ExplorationType, set_exploration_type

from torchrl_subgoal.potentials import TabularPotential
from torchrl_subgoal.training.config import LearnerConfig
from torchrl_subgoal.training.envs import Shaping, shaped_env
from torchrl_subgoal.training.recording import LearningCurve, SuccessSignal
from torchrl_subgoal.training.stack import per_learner
from torchrl_subgoal.training.subgoal_input import SUBGOAL_INDEX

__all__ = ["Evaluation", "Trained", "evaluate"]


@dataclass(frozen=True)
class Evaluation:
    """The greedy episodes of :func:`evaluate`, one entry per episode.

    Attributes:
        returns: env returns (the unshaped reward, env units).
        lengths: steps.
        success: whether each succeeded (:class:`~torchrl_subgoal.training.SuccessSignal`; ``NaN``: not measured).

    Examples:
        >>> Evaluation([1.0, 0.0], [8, 40], [1.0, 0.0]).mean_return
        0.5
    """

    returns: list[float]
    lengths: list[int]
    success: list[float]

    @property
    def mean_return(self) -> float:
        """Mean env return."""
        return sum(self.returns) / len(self.returns)

    @property
    def success_rate(self) -> float:
        """Fraction of the episodes that succeeded (``NaN``: not measured)."""
        return sum(self.success) / len(self.success)


def evaluate(
    policy: TensorDictModuleBase,
    make_env: Callable[[int], EnvBase],
    episodes: int = 10,
    *,
    max_steps: int | None = None,
    success: SuccessSignal | None = None,
    seed: int = 0,
) -> Evaluation:
    """``episodes`` greedy episodes of ``policy`` (deterministic exploration: the mode of a stochastic
    policy, no exploration noise), one on each env of ``make_env(episodes)``.

    Args:
        policy: what acts (e.g. :meth:`Trained.policy`); it must read only what the env writes (a policy
            that reads the subgoal index needs the shaping transform: :meth:`Trained.evaluate` adds it).
        make_env: ``make_env(num_envs)``.
        episodes: episodes (envs).
        max_steps: the longest episode (default: the env's ``max_steps``, else 10,000).
        success: how success is read (default: the env's ``"is_success"``/``"success"`` entry).
        seed: the envs' seed.

    Examples:
        >>> from tensordict.nn import TensorDictModule
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> down = TensorDictModule(lambda o: torch.zeros(o.shape[0], dtype=torch.long), ["observation"], ["action"])
        >>> result = evaluate(down, functools.partial(FourRoomsEnv, max_steps=30), 2,
        ...                   success=SuccessSignal(min_return=1.0))
        >>> result.lengths, result.returns, result.success  # always down: stuck at the wall, never the goal
        ([30, 30], [0.0, 0.0], [0.0, 0.0])
    """
    env = make_env(episodes)
    env.set_seed(seed)
    steps = max_steps or int(getattr(env, "max_steps", None) or getattr(env.base_env, "max_steps", 0) or 10_000)
    reward_key = "env_reward" if "env_reward" in env.reward_keys else env.reward_key
    try:
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            data = env.rollout(steps, policy, break_when_any_done=False, break_when_all_done=True).reshape(episodes, -1)
    finally:
        env.close(raise_if_closed=False)
    nxt = data.get("next")
    done = nxt.get("done").reshape(episodes, -1)
    length = torch.where(done.any(1), done.float().argmax(1) + 1, torch.full((episodes,), done.shape[1]))
    first = torch.arange(done.shape[1]).unsqueeze(0) < length.unsqueeze(1)  # each env's first episode
    returns = (nxt.get(reward_key).reshape(episodes, -1) * first).sum(1)
    last = nxt[torch.arange(episodes), length - 1]
    won = (success or SuccessSignal()).read(last, returns)
    return Evaluation(
        returns.tolist(),
        [int(n) for n in length],
        won.float().tolist() if won is not None else [math.nan] * episodes,
    )


@dataclass
class Trained:
    """What a building block returns: the learners' curves and their trained modules.

    Attributes:
        algo: the block's name (``"a2c"``, ``"ppo"``, ``"dqn"``, ``"ddpg"``).
        config: the learners' settings.
        seeds: one per learner.
        curves: one per learner.
        modules: the trained modules over every learner (stacked); ``"policy"`` is the greedy policy.
        observation_key: what the networks read.
        subgoal_states: the size of the one-hot ``z`` the networks read (0: they do not).
        shaping: the batch's shaping (its potential holds every learner's table), ``None`` unshaped.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import A2CConfig, train_a2c
        >>> config = A2CConfig(num_envs=4, frames_per_batch=64, total_frames=128, features="one_hot", hidden=())
        >>> trained = train_a2c(FourRoomsEnv, config, seeds=[0, 1])
        >>> len(trained.curves), sorted(trained.modules)
        (2, ['actor', 'critic', 'policy'])
        >>> trained.evaluate(functools.partial(FourRoomsEnv, max_steps=20), episodes=2, learner=1).lengths
        [20, 20]
    """

    algo: str
    config: LearnerConfig
    seeds: list[int]
    curves: list[LearningCurve]
    modules: dict[str, nn.Module]
    observation_key: NestedKey = "observation"
    subgoal_states: int = 0
    shaping: Shaping | None = field(default=None, repr=False)

    @property
    def curve(self) -> LearningCurve:
        """The curve of a single learner."""
        if len(self.curves) != 1:
            raise ValueError(f"{len(self.curves)} learners have a curve each: read curves[k]")
        return self.curves[0]

    def policy(self, learner: int = 0) -> TensorDictModuleBase:
        """Learner ``learner``'s greedy policy, a module of its own for any number of envs (on the CPU)."""
        self._check(learner)
        module = per_learner(self.modules["policy"], learner).to("cpu")
        assert isinstance(module, TensorDictModuleBase)
        return module

    def potential(self, learner: int = 0) -> nn.Module | None:
        """Learner ``learner``'s shaping potential (a table's copy, frozen), ``None`` unshaped."""
        self._check(learner)
        if self.shaping is None:
            return None
        potential = self.shaping.potential
        if isinstance(potential, TabularPotential) and potential.batch_shape:
            own = TabularPotential(potential.num_states, monotone=potential.monotone, interpolate=potential.interpolate)
            return own.freeze(potential.table.detach()[learner].cpu())
        return potential

    def learner_shaping(self, learner: int = 0) -> Shaping | None:
        """Learner ``learner``'s shaping: its subgoals and its potential (frozen), ``None`` unshaped."""
        if self.shaping is None:
            return None
        subgoals = self.shaping.subgoals
        if isinstance(subgoals, list | tuple):
            subgoals = subgoals[learner * self.config.num_envs]
        potential = self.potential(learner)
        assert potential is not None
        return Shaping(subgoals, potential, dict(self.shaping.options))

    def evaluate(
        self, make_env: Callable[[int], EnvBase], episodes: int = 10, *, learner: int = 0, **kwargs: Any
    ) -> Evaluation:
        """:func:`evaluate` of learner ``learner``'s greedy policy on ``make_env`` (with its shaping transform,
        the potential fixed, when the policy reads the subgoal index)."""
        policy = self.policy(learner)
        shaping = self.learner_shaping(learner)
        if SUBGOAL_INDEX in policy.in_keys and shaping is not None:
            make_env = functools.partial(_shaped, make_env, shaping, self.config.gamma)
        return evaluate(policy, make_env, episodes, **kwargs)

    def save(self, path: str | Path) -> None:
        """Write the settings, seeds, curves and every module's state dict (TorchRL's / torch's) to ``path``."""
        torch.save(
            {
                "algo": self.algo,
                "config": dataclasses.asdict(self.config),
                "seeds": self.seeds,
                "curves": [dataclasses.asdict(c) for c in self.curves],
                "observation_key": self.observation_key,
                "subgoal_states": self.subgoal_states,
                "modules": {name: module.state_dict() for name, module in self.modules.items() if name != "policy"},
                "potential": self.shaping.potential.state_dict() if self.shaping is not None else None,
            },
            path,
        )

    def _check(self, learner: int) -> None:
        if not 0 <= learner < len(self.seeds):
            raise ValueError(f"learner {learner} is not one of the {len(self.seeds)} learners")


def _shaped(make_env: Callable[[int], EnvBase], shaping: Shaping, gamma: float, num_envs: int) -> EnvBase:
    return shaped_env(make_env, num_envs, shaping=shaping, gamma=gamma, episode_stats=False)
