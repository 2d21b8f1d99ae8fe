"""Tabular ε-greedy Q-learning on a TorchRL :class:`~torchrl.collectors.Collector`, batched over learners.

The first learner a TorchRL user writes: a table ``Q[s, a]`` (``Q[s, z, a]`` when
the learner sees the subgoal index ``z``), an ε-greedy policy module, a
``Collector`` over a batched env, and one Q-learning update per collected
step. Here every env of the batch is an independent learner with its own
table, so many seeds run as one batch: ``Q`` is ``[N, S, Z, A]`` and the
policy and the update index it by the env's position in the batch.

::

    env = TransformedEnv(FourRoomsEnv(num_envs=20, goal_reward=0.0, step_reward=-1.0), shaping)
    trained = train_qlearning(env, QLearningConfig(episodes=300), seed=0, success=SuccessSignal(min_return=-999))
    trained.records.steps    # [20, 300] steps of every learner's episodes
    trained.policy(3)        # learner 3's greedy policy
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.collectors import Collector
from torchrl.data import Categorical, OneHot
from torchrl.envs import EnvBase, ExplorationType
from torchrl.envs.utils import exploration_type

from torchrl_subgoal.fused._kernels.records import record_episodes
from torchrl_subgoal.fused.records import EpisodeRecords
from torchrl_subgoal.training.config import Settings
from torchrl_subgoal.training.recording import SuccessSignal

__all__ = ["EpsilonGreedyQ", "QLearningConfig", "TrainedQ", "train_qlearning"]


@dataclass
class QLearningConfig(Settings):
    """Settings of a batch of tabular Q-learners (``gamma``, ``device``: :class:`~torchrl_subgoal.training.Settings`).

    Examples:
        >>> QLearningConfig(epsilon=1.5)
        Traceback (most recent call last):
        ...
        ValueError: epsilon must lie in [0, 1], got 1.5
    """

    episodes: int = 300
    """episodes recorded per learner (the run stops once every learner has them)"""
    lr: float = 0.1
    """the step size (alpha) of the update ``Q(s, a) += alpha * (r + gamma * max Q(s', .) - Q(s, a))``"""
    epsilon: float = 0.1
    """probability of a uniformly random action"""
    init: float = 0.0
    """initial value of every entry (0: optimistic under a step cost, pessimistic under a goal reward)"""
    sees_subgoal: bool = True
    """the table is over ``(s, z)`` (``z`` the transform's subgoal index): the shaped reward is then a
    function of the learner's own state"""
    max_frames: int = 0
    """a cap on collected steps per learner (``0``: none); learners that have not finished their episodes
    by then keep ``max_steps``-long placeholder episodes"""


class EpsilonGreedyQ(TensorDictModuleBase):
    """A batch of Q tables and their ε-greedy policy: row ``b`` of the env batch acts with table ``b``.

    Ties between greedy actions are broken uniformly at random (a zero-initialised
    table would otherwise always pick the first action).

    Args:
        learners: the env batch size (one table per env).
        states: number of states (the observation is a state number).
        actions: number of actions.
        abstract_states: number of subgoal indices ``z`` the table distinguishes (1: it ignores ``z``).
        epsilon: probability of a uniformly random action.
        init: initial value of every entry.
        generator: the random draws' generator.

    Keyword Args:
        observation_key: the state number read.
        subgoal_key: the subgoal index read when ``abstract_states > 1``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> policy = EpsilonGreedyQ(2, states=3, actions=2, epsilon=0.0, generator=torch.Generator().manual_seed(0))
        >>> policy.table[1, 0, 0, 1] = 1.0
        >>> policy(TensorDict({"observation": torch.tensor([0, 0])}, [2]))["action"][1].item()
        1
    """

    def __init__(
        self,
        learners: int,
        states: int,
        actions: int,
        abstract_states: int = 1,
        epsilon: float = 0.1,
        init: float = 0.0,
        generator: torch.Generator | None = None,
        *,
        observation_key: NestedKey = "observation",
        subgoal_key: NestedKey = "subgoal_index",
    ) -> None:
        super().__init__()
        self.observation_key, self.subgoal_key = observation_key, subgoal_key
        self.in_keys = [observation_key] + ([subgoal_key] if abstract_states > 1 else [])
        self.out_keys = ["action"]
        self.register_buffer("table", torch.full((learners, states, abstract_states, actions), float(init)))
        self.epsilon = float(epsilon)
        self.generator = generator if generator is not None else torch.Generator()
        self.rows = torch.arange(learners)

    table: torch.Tensor

    def learner(self, k: int) -> EpsilonGreedyQ:
        """Learner ``k``'s table as a policy of its own (for any number of envs)."""
        _, states, abstract, actions = self.table.shape
        own = EpsilonGreedyQ(
            1,
            states,
            actions,
            abstract,
            self.epsilon,
            observation_key=self.observation_key,
            subgoal_key=self.subgoal_key,
        )
        own.table.copy_(self.table[k : k + 1])
        return own

    def index(self, td: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        """The ``(s, z)`` of every row of ``td`` (``z = 0`` when the table ignores it)."""
        s = td.get(self.observation_key).reshape(-1).long()
        z = td.get(self.subgoal_key).reshape(-1).long() if self.table.shape[2] > 1 else torch.zeros_like(s)
        return s, z

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        s, z = self.index(tensordict)
        rows = self.rows if len(self.rows) == len(s) or len(self.rows) > 1 else torch.zeros_like(s)  # one table: all
        q = self.table[rows, s, z]  # [N, A]
        if exploration_type() not in (ExplorationType.RANDOM, None):  # greedy, the first best action
            tensordict.set("action", q.argmax(-1).reshape(tensordict.batch_size))
            return tensordict
        best = q == q.max(-1, keepdim=True).values
        weights = best.float() + 1e-30  # uniform over the greedy actions
        greedy = torch.multinomial(weights, 1, generator=self.generator).squeeze(-1)
        uniform = torch.randint(q.shape[-1], greedy.shape, generator=self.generator)
        explore = torch.rand(greedy.shape, generator=self.generator) < self.epsilon
        action = torch.where(explore, uniform, greedy)
        tensordict.set("action", action.reshape(tensordict.batch_size))
        return tensordict


@dataclass
class TrainedQ:
    """What :func:`train_qlearning` returns: every learner's episodes and the tables.

    Attributes:
        records: steps, env return and success of every learner's episodes.
        q: the tables (``[N, S, Z, A]``) and their ε-greedy policy.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import evaluate
        >>> trained = train_qlearning(FourRoomsEnv(2), QLearningConfig(episodes=1, sees_subgoal=False))
        >>> evaluate(trained.policy(1), FourRoomsEnv, 1).lengths  # greedy on learner 1's table
        [1000]
    """

    records: EpisodeRecords
    q: EpsilonGreedyQ

    def policy(self, learner: int = 0) -> EpsilonGreedyQ:
        """Learner ``learner``'s table as a policy (greedy under deterministic exploration, e.g. in
        :func:`~torchrl_subgoal.training.evaluate`)."""
        return self.q.learner(learner)


def train_qlearning(
    env: EnvBase,
    config: QLearningConfig,
    *,
    observation_key: NestedKey = "observation",
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
    success: SuccessSignal | None = None,
) -> TrainedQ:
    """Train one tabular Q-learner per env of the batched ``env`` on a ``Collector``; every learner's episodes
    and tables.

    ``env`` may carry a :class:`~torchrl_subgoal.SubgoalPotentialTransform`: the learners
    then learn from the shaped ``"reward"`` and the records keep the env's own return
    (``"env_reward"``). The potential is trained as the transform was built to (online
    with ``value_update``, or not at all).

    Args:
        env: a batched env with a categorical observation ``observation_key`` and discrete actions.
        config: the settings.
        observation_key: the state number the tables are indexed by.
        seed: seeds the policy's draws (the env is seeded with it too).
        progress: called with the number of learner-episodes just finished.
        success: how an episode's success is read (default: the env's ``"is_success"``/``"success"``
            entry); where it is not measured, every episode's success is recorded as ``False``.

    Returns:
        the records (steps, env return and success of every learner's first ``config.episodes`` episodes)
        and the tables.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import SuccessSignal
        >>> trained = train_qlearning(FourRoomsEnv(3, goal_reward=0.0, step_reward=-1.0),
        ...                           QLearningConfig(episodes=2, sees_subgoal=False), seed=0,
        ...                           success=SuccessSignal(min_return=-999.0))
        >>> trained.records.steps.shape, bool(trained.records.success.all()), trained.q.table.shape
        (torch.Size([3, 2]), True, torch.Size([3, 104, 1, 4]))
    """
    n = max(1, env.batch_size.numel())
    obs_spec = env.observation_spec[observation_key]
    act_spec = env.full_action_spec[env.action_key]
    if not isinstance(obs_spec, Categorical | OneHot) or isinstance(obs_spec, OneHot):
        raise ValueError(
            f"tabular Q-learning needs a categorical observation {observation_key!r}, got {type(obs_spec).__name__}"
        )
    if not isinstance(act_spec, Categorical):
        raise ValueError(f"tabular Q-learning needs categorical actions, got {type(act_spec).__name__}")
    abstract = 1
    if config.sees_subgoal and "subgoal_index" in env.observation_spec:
        abstract = int(env.observation_spec["subgoal_index"].space.high.max()) + 1
    generator = torch.Generator().manual_seed(seed)
    policy = EpsilonGreedyQ(
        n,
        int(obs_spec.space.n),
        int(act_spec.space.n),
        abstract,
        config.epsilon,
        config.init,
        generator,
        observation_key=observation_key,
    )
    return_key = "env_reward" if "env_reward" in env.reward_keys else "reward"
    signal = success if success is not None else SuccessSignal()
    episodes = config.episodes
    steps = torch.zeros(n, episodes, dtype=torch.long)
    returns = torch.zeros(n, episodes)
    successes = torch.zeros(n, episodes, dtype=torch.bool)
    outputs = (steps.numpy(), returns.numpy(), successes.numpy())
    t, ret, filed = np.zeros(n, np.int64), np.zeros(n), np.zeros(n, np.int64)
    env.set_seed(seed)
    collector = Collector(env, policy, frames_per_batch=n, total_frames=-1, auto_register_policy_transforms=False)
    table, rows, lr, gamma = policy.table, policy.rows, config.lr, config.gamma
    frames, flagged = 0, False
    try:
        for data in collector:
            data = data.reshape(-1)  # one step of every learner
            nxt = data.get("next")
            s, z = policy.index(data)
            s2, z2 = policy.index(nxt)
            a = data.get("action").reshape(-1)
            reward = nxt.get("reward").reshape(-1)
            terminated = nxt.get("terminated").reshape(-1)
            target = reward + gamma * table[rows, s2, z2].max(-1).values.masked_fill(terminated, 0.0)
            table[rows, s, z, a] += lr * (target - table[rows, s, z, a])
            frames += 1
            done = nxt.get("done").reshape(-1)
            won = signal.at_end(nxt)  # the step's success flag, filed where an episode ends
            flagged = won is not None
            won = won if won is not None else torch.zeros_like(done)
            count = record_episodes(
                done.numpy(), won.numpy(), nxt.get(return_key).reshape(-1).numpy(), t, ret, filed, *outputs
            )
            if count and progress is not None:
                progress(count)
            if filed.min() >= episodes or (config.max_frames and frames >= config.max_frames):
                break
    finally:
        collector.shutdown()
    short = filed < episodes
    if short.any():  # capped: the missing episodes count as failures of the env's length
        cap = (
            float(getattr(env, "max_steps", math.nan))
            if not hasattr(env, "base_env")
            else float(getattr(env.base_env, "max_steps", math.nan))
        )
        for b in np.nonzero(short)[0]:
            steps[b, filed[b] :] = int(cap) if math.isfinite(cap) else frames
    if signal.min_return is not None and not flagged:  # success read from the returns
        successes.copy_(returns >= signal.min_return)
    return TrainedQ(EpisodeRecords(steps, returns, successes, frames * n), policy)
