"""DDPG from TorchRL parts: normaliser, clipped target, exploration, soft update, saved state."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.data import Bounded
from torchrl.envs import ExplorationType, set_exploration_type

from torchrl_subgoal.training.ddpg_parts import DDPGAgent, DDPGConfig, RunningNorm, TD3Settings

SPEC = Bounded(-1.0, 1.0, shape=(4,))


def batch(n: int, reward: float = -1.0, seed: int = 0) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    return TensorDict(
        {
            "observation": torch.randn(n, 6, generator=g),
            "action": torch.rand(n, 4, generator=g) * 2 - 1,
            "next": {
                "observation": torch.randn(n, 6, generator=g),
                "reward": torch.full((n, 1), reward),
                "done": torch.zeros(n, 1, dtype=torch.bool),
                "terminated": torch.zeros(n, 1, dtype=torch.bool),
            },
        },
        [n],
    )


def agent(**overrides) -> DDPGAgent:
    torch.manual_seed(0)
    return DDPGAgent(6, SPEC, DDPGConfig(**{"hidden": (16, 16), "batch_size": 8, **overrides}))


def test_running_norm_matches_numpy_and_clips() -> None:
    x = np.random.default_rng(0).normal(3.0, 2.0, size=(500, 3))
    norm = RunningNorm(3, eps=0.01, clip=5.0)
    norm.update(torch.tensor(x[:200], dtype=torch.float32))
    norm.update(torch.tensor(x[200:], dtype=torch.float32))
    np.testing.assert_allclose(norm.mean[0].numpy(), x.mean(0), rtol=1e-5)  # one learner's statistics
    np.testing.assert_allclose(norm.std[0].numpy(), x.std(0), rtol=1e-4)
    out = norm(torch.tensor([[3.0, 3.0, 1000.0]]))
    assert out[0, 2].item() == 5.0 and abs(out[0, 0].item()) < 0.2


def test_target_is_clipped_to_the_return_range() -> None:
    a = agent()
    for reward, low, high in ((100.0, None, 0.0), (-1e4, -50.0, None)):
        data = batch(8, reward)
        data.set("observation_normalized", data["observation"])
        data.set(("next", "observation_normalized"), data["next", "observation"])
        target = a.loss.value_estimator.value_estimate(data, target_params=a.loss._cached_target_params)
        with torch.no_grad():
            nxt = data["next"].select("observation_normalized").clone()
            a.actor(nxt)
            unclipped = reward + 0.98 * a.critic(nxt)["state_action_value"]
        expected = unclipped.clamp(low, high)
        assert torch.allclose(target, expected)
        assert not torch.allclose(target, unclipped)


def test_exploration_noise_and_random_actions() -> None:
    obs = TensorDict({"observation": torch.randn(2000, 6)}, [2000])
    greedy = agent(random_eps=0.0, noise_eps=0.0)
    with torch.no_grad():
        assert torch.equal(greedy.policy(obs.clone())["action"], greedy.greedy(obs.clone())["action"])
    noisy = agent(random_eps=0.3, noise_eps=0.2)
    with torch.no_grad():
        explored = noisy.policy(obs.clone())["action"]
        mean = noisy.greedy(obs.clone())["action"]
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            assert torch.equal(noisy.policy(obs.clone())["action"], mean)
    assert explored.abs().max() <= 1.0
    far = (explored - mean).abs().max(-1).values > 0.8  # Gaussian noise of s.d. 0.2 rarely moves this far
    assert 0.15 < far.float().mean() < 0.3  # most of the 30% random actions do


def test_update_and_soft_update() -> None:
    a = agent(polyak=0.95)
    a.extend(batch(64))
    before = {k: v.clone() for k, v in a.loss.target_value_network_params.items(True, True)}
    online_before = a.loss.value_network_params.clone()
    losses = a.update()
    assert set(losses) == {"loss_value", "loss_actor"}
    first = ("module", "params", "net", "0", "weight")  # the critic's first layer (stacked over one learner)
    assert not torch.equal(a.loss.value_network_params[first], online_before[first])
    a.soft_update()
    for key, old in before.items():
        expected = 0.95 * old + 0.05 * a.loss.value_network_params[key]
        assert torch.allclose(a.loss.target_value_network_params[key], expected, atol=1e-6)


@pytest.mark.parametrize("td3", [False, True])
def test_soft_update_is_torchrl_soft_update_bit_for_bit(td3: bool) -> None:
    torch.manual_seed(0)
    config = DDPGConfig(hidden=(16, 16), batch_size=8, action_l2=0.0)
    a = DDPGAgent(6, SPEC, config, td3=TD3Settings(policy_delay=1) if td3 else None)
    a.extend(batch(64))
    a.update()
    before = {k: v.clone() for k, v in a.loss.state_dict().items()}
    a.target_updater.step()  # TorchRL's SoftUpdate
    expected = {k: v.clone() for k, v in a.loss.state_dict().items()}
    a.loss.load_state_dict(before)
    a.soft_update()
    after = a.loss.state_dict()
    assert any(not torch.equal(expected[k], before[k]) for k in expected)
    assert all(torch.equal(after[k], expected[k]) for k in expected)


def test_training_state_round_trip() -> None:
    a, b = agent(), agent(batch_size=8)
    a.extend(batch(32))
    a.update()
    b.load_training_state(a.training_state())
    obs = TensorDict({"observation": torch.randn(5, 6)}, [5])
    with torch.no_grad():
        assert torch.equal(a.greedy(obs.clone())["action"], b.greedy(obs.clone())["action"])
    assert torch.equal(a.norm.mean, b.norm.mean)
    with pytest.raises(ValueError, match="does not fit"):
        DDPGAgent(7, SPEC, DDPGConfig(hidden=(16, 16))).load_training_state(a.training_state())


def test_update_gradients_equal_ddpg_loss_plus_the_action_penalty() -> None:
    """One actor pass for Q and the L2 penalty gives DDPGLoss's gradients plus the penalty's."""
    a = agent(action_l2=1.0)
    a.extend(batch(64))
    torch.manual_seed(3)
    sample = a.replay.sample()
    a.replay.sample = lambda: sample.clone()  # type: ignore[method-assign]
    reference = sample.clone()
    reference.set("observation_normalized", a.norm(reference["observation"]))
    reference.set(("next", "observation_normalized"), a.norm(reference["next", "observation"]))
    losses = a.loss(reference).apply(lambda v: v.mean(), batch_size=[])  # the agent's loss is per sample
    penalty = a.actor(reference.select("observation_normalized"))["action"].square().mean()
    params = list(a.loss.actor_network_params.values(True, True)) + list(a.loss.value_network_params.values(True, True))
    expected = torch.autograd.grad(losses["loss_value"] + losses["loss_actor"] + penalty, params)
    captured: list[torch.Tensor] = []
    for optimizer in (a.critic_optimizer, a.actor_optimizer):  # read the gradients the update steps with
        optimizer.step = lambda *args, o=optimizer, **kw: captured.extend(  # type: ignore[method-assign]
            p.grad.clone() for g in o.param_groups for p in g["params"]
        )
    got = a.update()
    assert got["loss_value"].item() == pytest.approx(losses["loss_value"].item(), abs=1e-6)
    assert got["loss_actor"].item() == pytest.approx((losses["loss_actor"] + penalty).item(), abs=1e-6)
    by_ptr = {
        p.data_ptr(): g
        for p, g in zip(
            [p for o in (a.critic_optimizer, a.actor_optimizer) for g in o.param_groups for p in g["params"]],
            captured,
            strict=True,
        )
    }
    for p, e in zip(params, expected, strict=True):
        assert torch.allclose(by_ptr[p.data_ptr()], e, atol=1e-6, rtol=1e-5)
