"""A tiny batched corridor for the building blocks' learning tests: discrete or continuous moves.

The agent starts at 0 and must reach ``length``: discrete actions move one cell
left (0) or right (1); a continuous action ``a ∈ [-1, 1]`` moves by ``a``. The
position is clamped at 0. Reaching ``length`` terminates with reward 1 (0
otherwise); ``max_steps`` truncates. The observation is the position divided by
``length`` (a float in ``[0, 1]``). A random policy rarely gets there within
``max_steps`` (a reflected random walk needs about ``length²`` steps); the
optimum takes ``length`` steps.
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase


class Corridor(EnvBase):
    batch_locked = True

    def __init__(self, num_envs: int = 1, length: int = 8, continuous: bool = False, max_steps: int = 40) -> None:
        super().__init__(batch_size=torch.Size([num_envs]))
        self.length, self.continuous, self.max_steps = length, continuous, max_steps
        n = (num_envs,)
        self.observation_spec = Composite(observation=Bounded(0.0, 1.0, shape=(*n, 1), dtype=torch.float32), shape=n)
        if continuous:
            self.action_spec = Bounded(-1.0, 1.0, shape=(*n, 1), dtype=torch.float32)
        else:
            self.action_spec = Categorical(2, shape=n, dtype=torch.long)
        self.reward_spec = Unbounded(shape=(*n, 1))
        self.done_spec = Composite(
            {key: Categorical(2, (*n, 1), dtype=torch.bool) for key in ("done", "terminated", "truncated")}, shape=n
        )
        self.pos = torch.zeros(num_envs)
        self.steps = torch.zeros(num_envs, dtype=torch.long)

    def _obs(self) -> torch.Tensor:
        return (self.pos / self.length).unsqueeze(-1).clone()

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        reset = tensordict.get("_reset", None) if tensordict is not None else None
        mask = torch.ones_like(self.pos, dtype=torch.bool) if reset is None else reset.reshape(-1)
        self.pos.masked_fill_(mask, 0.0)
        self.steps.masked_fill_(mask, 0)
        false = torch.zeros(*self.batch_size, 1, dtype=torch.bool)
        return TensorDict(
            {"observation": self._obs(), "done": false, "terminated": false.clone(), "truncated": false.clone()},
            self.batch_size,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action")
        move = action.reshape(-1).clamp(-1.0, 1.0) if self.continuous else action.reshape(-1).float() * 2 - 1
        self.pos = (self.pos + move).clamp(0.0, float(self.length))
        self.steps += 1
        terminated = (self.pos >= self.length).unsqueeze(-1)
        truncated = (self.steps >= self.max_steps).unsqueeze(-1) & ~terminated
        return TensorDict(
            {
                "observation": self._obs(),
                "reward": terminated.float(),
                "done": terminated | truncated,
                "terminated": terminated,
                "truncated": truncated,
            },
            self.batch_size,
        )

    def _set_seed(self, seed: int | None) -> None:
        pass


def discrete_corridor(num_envs: int) -> Corridor:
    """``make_env(num_envs)`` of the discrete corridor (importable by worker processes)."""
    return Corridor(num_envs)


def continuous_corridor(num_envs: int) -> Corridor:
    """``make_env(num_envs)`` of the continuous corridor."""
    return Corridor(num_envs, length=5, continuous=True)
