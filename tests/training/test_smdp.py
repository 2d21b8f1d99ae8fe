"""Real SMDP transitions of collected data, into a replay buffer, for a per-env potential."""

from __future__ import annotations

import torch
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.envs import TransformedEnv

from torchrl_subgoal import (
    Cell,
    SubgoalPotentialTransform,
    SubgoalSeries,
    SubgoalValueLoss,
    TabularPotential,
)
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.training import extend_transitions, smdp_transitions


def test_replay_of_real_transitions_trains_per_env_tables_like_the_paper_update() -> None:
    """Shuffled transitions from a replay buffer find their env's table by the learner key: one SGD
    step on all of them equals the per-env tabular updates (sum reduction)."""
    n, gamma, lr = 4, 0.9, 0.1
    v = TabularPotential(3, (n,))
    with torch.no_grad():
        v.table.copy_(torch.randn(n, 3, generator=torch.Generator().manual_seed(0)))
    t = SubgoalPotentialTransform(SubgoalSeries([Cell(1, 2), Cell(2, 2)]), v, gamma=gamma, observation_key="cell")
    torch.manual_seed(1)
    data = TransformedEnv(FourRoomsEnv(n, max_steps=15), t).rollout(120, break_when_any_done=False)
    buffer = ReplayBuffer(storage=LazyTensorStorage(1000))
    count = extend_transitions(buffer, data, t)
    assert count == len(buffer) and 0 < count < data.numel() // 2  # only the real ones
    sample = buffer[:count][torch.randperm(count)]  # shuffled: positions say nothing of the env
    before = v.table.detach().clone()
    expected = before.clone()
    for row in smdp_transitions(data, t).unbind(0):  # the paper's update, one transition at a time
        b, z, z2 = int(row["subgoal_learner"]), int(row["subgoal_index"]), int(row["next", "subgoal_index"])
        target = float(row["next", "reward"]) + gamma ** int(row["steps_to_next_obs"]) * (
            0.0 if bool(row["next", "terminated"]) else float(before[b, z2])
        )
        expected[b, z] += lr * (target - float(before[b, z]))
    loss = SubgoalValueLoss(v, expectile=0.5, bootstrap_truncated=True).make_value_estimator(gamma=gamma)
    optimizer = torch.optim.SGD(v.parameters(), lr=lr)
    loss(sample)["loss_value"].backward()
    optimizer.step()
    assert torch.allclose(v.table.detach(), expected, atol=1e-5)
    assert not torch.allclose(expected, before)
