"""Envs for the transform's TorchRL contract: agents in a group with nested keys, and an env that resets
itself during its step (TorchRL's native auto-reset)."""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from .line_env import LineEnv


class AgentsLineEnv(EnvBase):
    """``agents`` walkers per env, each on its own line 0..length, under the nested key ``"agents"``: each
    agent's episode ends on its own (``("agents", "done")``), as in a multi-agent env with per-agent dones."""

    batch_locked = True

    def __init__(self, num_envs: int = 2, agents: int = 3, length: int = 4) -> None:
        super().__init__(batch_size=torch.Size([num_envs]))
        self.length = length
        group = (num_envs, agents)
        self.observation_spec = Composite(
            agents=Composite(observation=Categorical(length + 1, shape=group, dtype=torch.long), shape=group),
            shape=(num_envs,),
        )
        self.action_spec = Composite(
            agents=Composite(action=Categorical(2, shape=group, dtype=torch.long), shape=group), shape=(num_envs,)
        )
        self.reward_spec = Composite(
            agents=Composite(reward=Unbounded(shape=(*group, 1)), shape=group), shape=(num_envs,)
        )
        flag = Categorical(2, shape=(*group, 1), dtype=torch.bool)
        self.done_spec = Composite(agents=Composite(done=flag, terminated=flag.clone(), shape=group), shape=(num_envs,))
        self.pos = torch.zeros(group, dtype=torch.long)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        reset = tensordict.get(("agents", "_reset"), None) if tensordict is not None else None
        self.pos = self.pos.masked_fill(reset.squeeze(-1), 0) if reset is not None else torch.zeros_like(self.pos)
        false = torch.zeros(*self.pos.shape, 1, dtype=torch.bool)
        return TensorDict(
            {
                "agents": TensorDict(
                    {"observation": self.pos.clone(), "done": false, "terminated": false.clone()}, self.pos.shape
                )
            },
            self.batch_size,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        self.pos = (self.pos + tensordict.get(("agents", "action")) * 2 - 1).clamp(0, self.length)
        terminated = (self.pos == self.length).unsqueeze(-1)
        agents = {
            "observation": self.pos.clone(),
            "reward": torch.where(terminated, 10.0, 1.0),
            "done": terminated,
            "terminated": terminated.clone(),
        }
        return TensorDict({"agents": TensorDict(agents, self.pos.shape)}, self.batch_size)

    def _set_seed(self, seed: int | None) -> None:
        pass


class AutoResetLineEnv(LineEnv):
    """:class:`LineEnv` that resets an env itself in the step that ends its episode (its ``"observation"``
    in ``"next"`` is then the reset one), flagged for TorchRL's native auto-reset."""

    def __init__(self, num_envs: int = 1, length: int = 4) -> None:
        super().__init__(num_envs, length)
        self._torchrl_native_autoreset = True

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        out = super()._step(tensordict)
        self.pos = self.pos.masked_fill(out["done"].squeeze(-1), 0)
        out.set("observation", self.pos.clone())
        return out
