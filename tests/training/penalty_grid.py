"""A small grid with a step cost and a costly idle action: the regime where a potential learned as the mean
return of the agent's own early episodes pays it to wander.

``width × width`` cells, start at the top-left corner, goal (terminal) at the bottom-right one. Actions: the
four moves (clamped at the walls) cost −1; the fifth, "idle", stays and costs ``penalty``. Episodes are
truncated after ``max_steps``. The observation is the cell number ``row · width + col``. A random policy
idles a fifth of the time, so its early returns are far below the optimal ones (the optimum takes
``2 (width − 1)`` steps). ``"success"`` says an episode reached the goal (its only termination).
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

MOVES = torch.tensor([[-1, 0], [1, 0], [0, -1], [0, 1], [0, 0]])


class PenaltyGrid(EnvBase):
    batch_locked = True

    def __init__(self, num_envs: int, width: int = 10, max_steps: int = 200, penalty: float = -10.0) -> None:
        super().__init__(batch_size=torch.Size([num_envs]))
        self.width, self.max_steps, self.penalty = width, max_steps, penalty
        n = (num_envs,)
        self.observation_spec = Composite(
            observation=Categorical(width * width, shape=n, dtype=torch.long),
            success=Categorical(2, (*n, 1), dtype=torch.bool),
            shape=n,
        )
        self.action_spec = Categorical(5, shape=n, dtype=torch.long)
        self.reward_spec = Unbounded(shape=(*n, 1))
        self.done_spec = Composite(
            {key: Categorical(2, (*n, 1), dtype=torch.bool) for key in ("done", "terminated", "truncated")}, shape=n
        )
        self.pos = torch.zeros(num_envs, 2, dtype=torch.long)
        self.steps = torch.zeros(num_envs, dtype=torch.long)

    def cell(self, row: int, col: int) -> int:
        """The observation of a cell."""
        return row * self.width + col

    def _obs(self) -> torch.Tensor:
        return self.pos[:, 0] * self.width + self.pos[:, 1]

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        reset = tensordict.get("_reset", None) if tensordict is not None else None
        mask = torch.ones(self.batch_size, dtype=torch.bool) if reset is None else reset.reshape(-1)
        self.pos[mask] = 0
        self.steps.masked_fill_(mask, 0)
        false = torch.zeros(*self.batch_size, 1, dtype=torch.bool)
        return TensorDict(
            {
                "observation": self._obs(),
                "success": false.clone(),
                "done": false,
                "terminated": false.clone(),
                "truncated": false.clone(),
            },
            self.batch_size,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action").reshape(-1)
        self.pos = (self.pos + MOVES[action]).clamp(0, self.width - 1)
        self.steps += 1
        terminated = (self.pos == self.width - 1).all(-1, keepdim=True)
        truncated = (self.steps >= self.max_steps).unsqueeze(-1) & ~terminated
        reward = torch.where(action == 4, self.penalty, -1.0).unsqueeze(-1)
        return TensorDict(
            {
                "observation": self._obs(),
                "success": terminated.clone(),
                "reward": reward,
                "done": terminated | truncated,
                "terminated": terminated,
                "truncated": truncated,
            },
            self.batch_size,
        )

    def _set_seed(self, seed: int | None) -> None:
        pass
