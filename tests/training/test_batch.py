"""Learners as a batch: stacked networks, per-learner losses and clipping, one table per learner."""

from __future__ import annotations

import copy

import pytest
import torch
from torch import nn
from torchrl.objectives import A2CLoss
from torchrl.objectives.value import GAE

from torchrl_subgoal import Cell, NaivePotential, SubgoalSeries, TabularPotential
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.training import Shaping, actor_critic
from torchrl_subgoal.training.batch import (
    LearnerStack,
    batch_shaping,
    clip_grad_norm_per_learner,
    learner_means,
    learner_rows,
    stack_actor_critic,
)

HALLWAYS = SubgoalSeries([Cell(3, 6), Cell(7, 9)])


class _TwoInputs(nn.Module):
    def __init__(self) -> None:
        super().__init__()
        self.linear = nn.Linear(5, 4)

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.linear(torch.cat([x, y], -1))


def test_each_learner_rows_go_through_its_own_network_with_several_inputs() -> None:
    torch.manual_seed(0)
    nets = [_TwoInputs() for _ in range(3)]
    stack = LearnerStack(nets)
    x, y = torch.randn(6, 5, 3), torch.randn(6, 5, 2)  # 3 learners x 2 envs, 5 steps
    out = stack(x, y)
    for k, rows in enumerate(learner_rows(3, 6)):
        torch.testing.assert_close(out[rows], nets[k](x[rows], y[rows]))
    assert [p.shape[0] for p in stack.parameters()] == [3, 3]
    with pytest.raises(ValueError, match="got 5 rows: not a multiple of 3"):
        stack(torch.randn(5, 3), torch.randn(5, 2))


def test_each_learner_gets_the_a2c_gradient_it_gets_alone() -> None:
    """The batch's loss (the sum of the learners' means of TorchRL's per-sample A2C losses) gives every
    learner's parameters the gradient of its own A2C loss on its own rows."""
    learners, envs = 3, 4
    env = FourRoomsEnv(learners * envs, max_steps=30, step_reward=-1.0)
    pairs = []
    for seed in range(learners):
        torch.manual_seed(seed)
        actor, critic = actor_critic(env, features="one_hot", hidden=(8,))
        with torch.no_grad():  # away from the uniform start, where the entropy's gradient is 0
            for p in [*actor.parameters(), *critic.parameters()]:
                p.add_(0.3 * torch.randn_like(p))
        pairs.append((actor, critic))
    alone_pairs = copy.deepcopy(pairs)
    actor, critic = stack_actor_critic(pairs)
    torch.manual_seed(5)
    data = env.rollout(40, actor, break_when_any_done=False)
    with torch.no_grad():
        GAE(gamma=0.9, lmbda=0.95, value_network=critic)(data)
    loss = A2CLoss(actor, critic, entropy_coeff=0.01, critic_coeff=0.5, loss_critic_type="l2", reduction="none")
    out = loss(data)
    names = ("loss_objective", "loss_critic", "loss_entropy")
    sum(learner_means(out[n], learners).sum() for n in names).backward()
    batch_grads = [p.grad for p in loss.parameters()]
    for k, rows in enumerate(learner_rows(learners, learners * envs)):
        alone_actor, alone_critic = alone_pairs[k]
        alone = A2CLoss(alone_actor, alone_critic, entropy_coeff=0.01, critic_coeff=0.5, loss_critic_type="l2")
        mine = data[rows].exclude("advantage", "value_target", "state_value", ("next", "state_value"))
        with torch.no_grad():
            GAE(gamma=0.9, lmbda=0.95, value_network=alone_critic)(mine)
        torch.testing.assert_close(mine["advantage"], data[rows]["advantage"])
        parts = alone(mine)
        sum(parts[n] for n in names).backward()
        grads = [p.grad for p in alone.parameters()]
        assert len(grads) == len(batch_grads) and any(g.abs().sum() > 0 for g in grads)
        for g, batch_g in zip(grads, batch_grads, strict=True):
            torch.testing.assert_close(batch_g[k], g, atol=1e-6, rtol=1e-5)


def test_clipping_per_learner_equals_clipping_each_learner_alone() -> None:
    torch.manual_seed(1)
    stacked = [nn.Parameter(torch.zeros(3, 4, 2)), nn.Parameter(torch.zeros(3, 2))]
    for p in stacked:
        p.grad = torch.randn_like(p) * torch.tensor([0.01, 1.0, 10.0]).view(3, *[1] * (p.dim() - 1))
    alone = [[nn.Parameter(p[k].detach().clone()) for p in stacked] for k in range(3)]
    for k, params in enumerate(alone):
        for p, s in zip(params, stacked, strict=True):
            p.grad = s.grad[k].clone()
    norms = clip_grad_norm_per_learner(stacked, 1.0, 3)
    for k, params in enumerate(alone):
        assert float(norms[k]) == pytest.approx(float(nn.utils.clip_grad_norm_(params, 1.0)), rel=1e-5)
        for p, s in zip(params, stacked, strict=True):
            torch.testing.assert_close(s.grad[k], p.grad)
    with pytest.raises(ValueError, match="not stacked over 2 learners"):
        clip_grad_norm_per_learner(stacked, 1.0, 2)


def test_batch_shaping_gives_each_learner_its_table_and_series() -> None:
    other = SubgoalSeries([Cell(7, 9)])
    first, second = TabularPotential(3), TabularPotential(2)
    with torch.no_grad():
        first.table.copy_(torch.tensor([0.1, 0.2, 0.3]))
    shaping = batch_shaping(
        [Shaping(HALLWAYS, first, {"observation_key": "cell"}), Shaping([other], second, {"observation_key": "cell"})],
        2,
    )
    assert shaping is not None and shaping.subgoals == [HALLWAYS, HALLWAYS, other, other]
    potential = shaping.potential
    assert isinstance(potential, TabularPotential) and potential.envs_per_table == 2 and potential.learners == 4
    torch.testing.assert_close(potential.table.detach(), torch.tensor([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]]))
    assert potential.table.requires_grad and shaping.options == {"observation_key": "cell"}
    frozen = batch_shaping([Shaping(HALLWAYS, TabularPotential(3).freeze([1.0, 2.0, 3.0])) for _ in range(2)], 2)
    assert frozen is not None and not frozen.potential.table.requires_grad
    naive = NaivePotential(0.5)
    assert batch_shaping([Shaping(HALLWAYS, naive), Shaping(HALLWAYS, NaivePotential(0.5))], 3).potential is naive


@pytest.mark.parametrize(
    ("shapings", "match"),
    [
        ([Shaping(HALLWAYS, TabularPotential(3)), None], "mix shaped and unshaped"),
        (
            [Shaping(HALLWAYS, TabularPotential(3)), Shaping(HALLWAYS, TabularPotential(3).freeze([0, 0, 0]))],
            "mix frozen and trained",
        ),
        ([Shaping(HALLWAYS, TabularPotential(3)), Shaping(HALLWAYS, TabularPotential(3), {"gamma": 0.5})], "options"),
        ([Shaping(HALLWAYS, NaivePotential(0.5)), Shaping(HALLWAYS, NaivePotential(1.0))], "different eta"),
        ([Shaping(HALLWAYS, TabularPotential(3)), Shaping(HALLWAYS, NaivePotential(1.0))], "one TabularPotential"),
        (
            [Shaping([HALLWAYS, HALLWAYS, HALLWAYS], TabularPotential(3)), Shaping(HALLWAYS, TabularPotential(3))],
            "given 3 subgoal series",
        ),
    ],
)
def test_batch_shaping_refuses_learners_it_cannot_batch(shapings: list, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        batch_shaping(shapings, 2)


def test_each_learner_gets_the_ppo_gradient_of_its_own_minibatch_alone() -> None:
    """A PPO minibatch of the batch is ``[K, size]``: each learner's advantages are standardised over its own
    minibatch and its parameters get the gradient of its own clipped PPO loss."""
    from torchrl.objectives import ClipPPOLoss

    learners, envs, size = 2, 4, 32
    env = FourRoomsEnv(learners * envs, max_steps=30, step_reward=-1.0)
    pairs = []
    for seed in range(learners):
        torch.manual_seed(seed)
        actor, critic = actor_critic(env, features="one_hot", hidden=(8,))
        with torch.no_grad():
            for p in [*actor.parameters(), *critic.parameters()]:
                p.add_(0.3 * torch.randn_like(p))
        pairs.append((actor, critic))
    alone_pairs = copy.deepcopy(pairs)
    actor, critic = stack_actor_critic(pairs)
    torch.manual_seed(5)
    with torch.no_grad():
        data = env.rollout(20, actor, break_when_any_done=False)
        GAE(gamma=0.9, lmbda=0.95, value_network=critic)(data)
    for key in [k for k in data.keys(include_nested=False) if isinstance(k, str) and k.endswith("log_prob")]:
        data[key] = data[key] + 0.3 * torch.randn_like(data[key])  # as if another policy acted: some ratios clip
    order = torch.randperm(envs * 20)[:size]
    batch_loss = ClipPPOLoss(
        actor, critic, normalize_advantage=True, normalize_advantage_exclude_dims=(0,), reduction="none"
    )
    out = batch_loss(data.reshape(learners, -1)[:, order])
    names = ("loss_objective", "loss_critic")
    torch.stack([learner_means(out[n], learners) for n in names]).sum().backward()
    batch_grads = [p.grad for p in batch_loss.parameters()]
    for k in range(learners):
        alone_actor, alone_critic = alone_pairs[k]
        alone = ClipPPOLoss(alone_actor, alone_critic, normalize_advantage=True)
        parts = alone(data.reshape(learners, -1)[k, order])
        sum(parts[n] for n in names).backward()
        for g, batch_g in zip([p.grad for p in alone.parameters()], batch_grads, strict=True):
            torch.testing.assert_close(batch_g[k], g, atol=1e-6, rtol=1e-5)
