"""z along a hand-made trajectory: the domains' subgoal tests run their series on stored observations."""

from __future__ import annotations

import torch
from tensordict import TensorDict

from torchrl_subgoal import SubgoalPotentialTransform, SubgoalSeries, TabularPotential


def subgoal_path(series: SubgoalSeries, observations: torch.Tensor) -> list[int]:
    """``z`` after each step of one trajectory of ``observations`` (``[T, D]``: ``T − 1`` steps), through the
    transform's forward on stored data (the reward and the potential do not change ``z``)."""
    transform = SubgoalPotentialTransform(series, TabularPotential(series.num_abstract_states), gamma=0.99)
    obs = observations.float()
    n = len(obs) - 1
    false = torch.zeros(1, n, 1, dtype=torch.bool)
    data = TensorDict(
        {
            "observation": obs[None, :-1],
            "next": {"observation": obs[None, 1:], "reward": torch.zeros(1, n, 1), "done": false, "terminated": false},
        },
        [1, n],
    )
    return transform(data)["next", "subgoal_index"].flatten().tolist()
