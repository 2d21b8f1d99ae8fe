"""A gymnasium env with a dict observation, for subgoal conditions on flags (not one of ours).

A corridor of cells 0..5: the key lies at cell 2 (picking it up sets the
``has_key`` flag), the door at cell 5 opens only with the key (reward 1,
terminated). Actions: 0 left, 1 right.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, GymWrapper

LENGTH, KEY, DOOR = 5, 2, 5


class KeyDoorEnv(gym.Env):
    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Dict(
            {"position": gym.spaces.Box(0, LENGTH, shape=(1,), dtype=np.float32), "has_key": gym.spaces.MultiBinary(1)}
        )
        self.action_space = gym.spaces.Discrete(2)
        self.position, self.has_key = 0, False

    def _obs(self) -> dict[str, np.ndarray]:
        return {"position": np.array([self.position], np.float32), "has_key": np.array([self.has_key], np.int8)}

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        self.position, self.has_key = 0, False
        return self._obs(), {}

    def step(self, action: int) -> tuple[dict, float, bool, bool, dict]:
        self.position = int(np.clip(self.position + (1 if action == 1 else -1), 0, LENGTH))
        self.has_key = self.has_key or self.position == KEY
        opened = self.position == DOOR and self.has_key
        return self._obs(), float(opened), opened, False, {}


def make_key_door() -> EnvBase:
    """The env wrapped for TorchRL (importable by spawned workers)."""
    return GymWrapper(KeyDoorEnv())


def carrying_key(td: TensorDictBase) -> torch.Tensor:
    """A subgoal condition on the dict observation's flag (module level: a subgoal file can name it)."""
    return td["has_key"].bool().squeeze(-1)


def at_door(td: TensorDictBase) -> torch.Tensor:
    return td["position"].squeeze(-1) >= DOOR
