"""A tiny deterministic env for hand-checked tests: a line of cells 0..length."""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from torchrl_subgoal.envs import FourRoomsEnv


class LineEnv(EnvBase):
    """Start at 0; action 1 moves right, 0 left; reward ``step_reward`` per step and
    ``goal_reward`` on reaching ``length`` (terminated)."""

    batch_locked = True

    def __init__(self, num_envs: int = 1, length: int = 4, step_reward: float = 1.0, goal_reward: float = 10.0):
        super().__init__(batch_size=torch.Size([num_envs]))
        self.length, self.step_reward, self.goal_reward = length, step_reward, goal_reward
        self.observation_spec = Composite(
            observation=Categorical(length + 1, shape=(num_envs,), dtype=torch.long), shape=(num_envs,)
        )
        self.action_spec = Categorical(2, shape=(num_envs,), dtype=torch.long)
        self.reward_spec = Unbounded(shape=(num_envs, 1))
        self.pos = torch.zeros(num_envs, dtype=torch.long)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        reset = tensordict.get("_reset", None) if tensordict is not None else None
        if reset is None:
            self.pos.zero_()
        else:
            self.pos.masked_fill_(reset.reshape(-1), 0)
        false = torch.zeros(*self.batch_size, 1, dtype=torch.bool)
        return TensorDict(
            {"observation": self.pos.clone(), "done": false, "terminated": false.clone()}, self.batch_size
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        move = tensordict.get("action") * 2 - 1
        self.pos = (self.pos + move).clamp(0, self.length)
        terminated = (self.pos == self.length).unsqueeze(-1)
        reward = torch.where(terminated, self.goal_reward, self.step_reward)
        return TensorDict(
            {"observation": self.pos.clone(), "reward": reward, "done": terminated, "terminated": terminated},
            self.batch_size,
        )

    def _set_seed(self, seed: int | None) -> None:
        pass


def make_four_rooms() -> FourRoomsEnv:
    """Factory for serial and parallel envs (importable by spawned workers)."""
    return FourRoomsEnv()
