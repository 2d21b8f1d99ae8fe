"""Every block's update of a batch of K learners is each learner's update alone: the same parameters (to
float tolerance) after steps on the same data, networks, targets, normalisers and Adam state included."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.data import Bounded

from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.training import (
    A2CConfig,
    A2CUpdate,
    DQNConfig,
    DQNUpdate,
    PPOConfig,
    PPOUpdate,
    actor_critic_modules,
    dqn_modules,
)
from torchrl_subgoal.training.ddpg_parts import DDPGAgent, DDPGConfig, TD3Settings

SEEDS = [3, 1, 4]
K = len(SEEDS)


def _learner_dim(alone: torch.Tensor, batch: torch.Tensor) -> int:
    """The dim of a batch's tensor that stacks the learners (size K where one learner's has 1)."""
    return next(d for d, (a, b) in enumerate(zip(alone.shape, batch.shape, strict=True)) if a != b)


def _tensors(module: nn.Module) -> list[tuple[str, torch.Tensor]]:
    return [*module.named_parameters(), *module.named_buffers()]


def _perturb(module: nn.Module) -> None:
    """Move every parameter off its start (output layers start at zero, where some gradients vanish)."""
    gen = torch.Generator().manual_seed(7)
    with torch.no_grad():
        for p in module.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=gen))


def _copy_learner(batch: nn.Module, alone: nn.Module, k: int) -> None:
    """Give one learner's module learner ``k``'s tensors of the batch's module (the same names)."""
    with torch.no_grad():
        for (name, b), (other, a) in zip(_tensors(batch), _tensors(alone), strict=True):
            assert name == other
            if a.shape == b.shape:  # not stacked (a step count, a shared constant)
                continue
            a.copy_(b.narrow(_learner_dim(a, b), k, 1))


def _assert_learners_equal(batch: nn.Module, alone: list[nn.Module], atol: float = 1e-5) -> None:
    checked = 0
    for k, one in enumerate(alone):
        for (name, b), (_, a) in zip(_tensors(batch), _tensors(one), strict=True):
            if a.shape == b.shape or not b.is_floating_point():
                continue
            torch.testing.assert_close(b.narrow(_learner_dim(a, b), k, 1), a, atol=atol, rtol=1e-4, msg=name)
            checked += 1
    assert checked > 0


def _rows(data: TensorDictBase, k: int) -> TensorDictBase:
    per = data.shape[0] // K
    return data[k * per : (k + 1) * per].clone()


def _rollout(env: FourRoomsEnv, policy: nn.Module, steps: int) -> TensorDictBase:
    torch.manual_seed(0)
    with torch.no_grad():
        return env.rollout(steps, policy, break_when_any_done=False)


def test_a2c_batch_updates_each_learner_as_alone() -> None:
    config = A2CConfig(features="one_hot", hidden=(8,), num_envs=2, frames_per_batch=40, normalize_advantage=True)
    probe = FourRoomsEnv(1, max_steps=12, step_reward=-1.0)
    batch = actor_critic_modules(probe, config, seeds=SEEDS)
    _perturb(batch["actor"]), _perturb(batch["critic"])
    alone = [actor_critic_modules(probe, config, seeds=[s]) for s in SEEDS]
    for k, one in enumerate(alone):
        _copy_learner(batch["actor"], one["actor"], k), _copy_learner(batch["critic"], one["critic"], k)
    data = _rollout(FourRoomsEnv(K * 2, max_steps=12, step_reward=-1.0), batch["actor"], 20)
    update = A2CUpdate(batch["actor"], batch["critic"], config, K)
    updates = [A2CUpdate(one["actor"], one["critic"], config, 1) for one in alone]
    for _ in range(2):
        losses = update(data.clone())
        for k, step in enumerate(updates):
            own = step(_rows(data, k))
            for name, value in own.items():
                torch.testing.assert_close(losses[name][k : k + 1], value, atol=1e-5, rtol=1e-4)
    _assert_learners_equal(
        nn.ModuleList([batch["actor"], batch["critic"]]), [nn.ModuleList([a["actor"], a["critic"]]) for a in alone]
    )


def test_ppo_batch_minibatch_step_updates_each_learner_as_alone() -> None:
    config = PPOConfig(features="one_hot", hidden=(8,), num_envs=2, frames_per_batch=40, minibatch_size=10)
    probe = FourRoomsEnv(1, max_steps=12, step_reward=-1.0)
    batch = actor_critic_modules(probe, config, seeds=SEEDS)
    _perturb(batch["actor"]), _perturb(batch["critic"])
    alone = [actor_critic_modules(probe, config, seeds=[s]) for s in SEEDS]
    for k, one in enumerate(alone):
        _copy_learner(batch["actor"], one["actor"], k), _copy_learner(batch["critic"], one["critic"], k)
    data = _rollout(FourRoomsEnv(K * 2, max_steps=12, step_reward=-1.0), batch["actor"], 20)
    update = PPOUpdate(batch["actor"], batch["critic"], config, K)
    updates = [PPOUpdate(one["actor"], one["critic"], config, 1) for one in alone]
    index = torch.tensor([5, 0, 33, 12, 7, 39, 21, 2, 18, 26])  # one minibatch, the same positions in each learner's
    for _ in range(2):
        with torch.no_grad():
            update.advantage(data)
        parts = update.step(data.reshape(K, -1)[:, index])
        for k, step in enumerate(updates):
            own = _rows(data, k)
            with torch.no_grad():
                step.advantage(own)
            torch.testing.assert_close(
                parts[:, k : k + 1], step.step(own.reshape(1, -1)[:, index]), atol=1e-5, rtol=1e-4
            )
    _assert_learners_equal(
        nn.ModuleList([batch["actor"], batch["critic"]]), [nn.ModuleList([a["actor"], a["critic"]]) for a in alone]
    )


def test_dqn_batch_gradient_step_updates_each_learner_and_its_target_as_alone() -> None:
    config = DQNConfig(
        features="one_hot", hidden=(8,), double_dqn=True, target_update_interval=2, max_grad_norm=0.5, lr=0.01
    )
    env = FourRoomsEnv(K * 4, max_steps=12, step_reward=-1.0)
    probe = FourRoomsEnv(1)
    spec = probe.full_action_spec_unbatched["action"]
    batch = dqn_modules(probe, config, seeds=SEEDS)["q"]
    alone = [dqn_modules(probe, config, seeds=[s])["q"] for s in SEEDS]
    update = DQNUpdate(batch, config, spec, K)
    updates = [DQNUpdate(q, config, spec, 1) for q in alone]
    _perturb(update.loss)
    for k, step in enumerate(updates):  # networks and targets
        _copy_learner(update.loss, step.loss, k)
    sample = _rollout(env, batch, 10).reshape(K, -1)  # [K, B]: each learner's transitions
    for _ in range(3):  # the third step follows a hard target update
        losses = update(sample.clone())
        for k, step in enumerate(updates):
            torch.testing.assert_close(losses[k : k + 1], step(sample[k : k + 1].clone()), atol=1e-5, rtol=1e-4)
    _assert_learners_equal(update.loss, [step.loss for step in updates])


def _ddpg_data(observation: int, action: int, rows: int) -> TensorDictBase:
    from tensordict import TensorDict

    gen = torch.Generator().manual_seed(11)
    return TensorDict(
        {
            "observation": torch.randn(rows, observation, generator=gen) * 3 + 1,
            "action": torch.rand(rows, action, generator=gen) * 2 - 1,
            "next": {
                "observation": torch.randn(rows, observation, generator=gen) * 3 + 1,
                "reward": -torch.rand(rows, 1, generator=gen),
                "done": torch.zeros(rows, 1, dtype=torch.bool),
                "terminated": torch.rand(rows, 1, generator=gen) < 0.1,
            },
        },
        [rows],
    )


def _check_ddpg(td3: TD3Settings | None) -> None:
    spec = Bounded(-1.0, 1.0, shape=(2,))
    config = DDPGConfig(hidden=(16, 16), batch_size=8, action_l2=0.0 if td3 else 0.5, clip_return=5.0)
    batch = DDPGAgent(3, spec, config, td3=td3, seeds=SEEDS)
    alone = [DDPGAgent(3, spec, config, td3=td3, seeds=[s]) for s in SEEDS]
    _perturb(batch.loss)
    for k, one in enumerate(alone):  # TD3's second critic is drawn by its loss: copied with the rest
        _copy_learner(batch.loss, one.loss, k)
    data = _ddpg_data(3, 2, K * 16)  # 16 transitions per learner, learner-major
    batch.extend(data)
    for k, one in enumerate(alone):
        one.extend(_rows(data, k))
    sample = batch.replay.sample()  # [K, B]
    for _ in range(4):  # TD3: the actor and the targets move every second step
        losses = batch.update_on(sample.clone())
        batch.soft_update()
        for k, one in enumerate(alone):
            own = one.update_on(sample[k : k + 1].clone())
            one.soft_update()
            for name, value in own.items():
                torch.testing.assert_close(losses[name][k : k + 1], value, atol=1e-5, rtol=1e-4)
    _assert_learners_equal(batch, alone)


def test_ddpg_batch_update_equals_each_learner_alone() -> None:
    _check_ddpg(None)


def test_td3_batch_update_equals_each_learner_alone() -> None:
    _check_ddpg(TD3Settings(policy_delay=2, target_noise=0.0))


def test_each_learner_samples_its_own_transitions() -> None:
    agent = DDPGAgent(3, Bounded(-1.0, 1.0, shape=(2,)), DDPGConfig(hidden=(8,), batch_size=64), seeds=SEEDS)
    data = _ddpg_data(3, 2, K * 16)
    data["observation"][:, 0] = torch.arange(K).repeat_interleave(16).float()  # the learner, in entry 0
    agent.extend(data)
    sample = agent.replay.sample()
    assert sample.batch_size == (K, 64)
    assert [sample["observation"][k, :, 0].unique().tolist() for k in range(K)] == [[0.0], [1.0], [2.0]]
    assert torch.allclose(agent.norm.mean[:, 0], torch.arange(K).float())  # each learner's normaliser its own
