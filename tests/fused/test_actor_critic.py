"""Fourier-basis actor-critic: features, and one update checked against autograd."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from torchrl_subgoal._kernels.random import draw_uniforms
from torchrl_subgoal.envs import PinBallEnv
from torchrl_subgoal.fused import AC_PRESETS, ActorCriticConfig, FourierActorCritic, run_episodes
from torchrl_subgoal.fused.actor_critic import fourier_coefficients

LOW, HIGH = [0.0, 0.0, -2.0, -2.0], [1.0, 1.0, 2.0, 2.0]


def test_features_are_cosines_of_the_scaled_state() -> None:
    agent = FourierActorCritic(1, LOW, HIGH, 5, AC_PRESETS["paper"])
    obs = torch.tensor([[0.3, 0.7, -1.0, 0.5], [1.2, -0.1, 3.0, 0.0]])  # the second is clipped to the cube
    scaled = ((obs.double() - torch.tensor(LOW).double()) / 4.0 * torch.tensor([4.0, 4.0, 1.0, 1.0])).clamp(0, 1)
    reference = torch.cos(torch.pi * scaled @ fourier_coefficients(3, 4).T)
    assert agent.num_features == 256
    assert torch.allclose(agent.features(obs), reference, atol=1e-12)


@pytest.mark.parametrize("normalize", [False, True])
def test_one_update_matches_autograd(normalize: bool) -> None:
    n, cfg = 3, ActorCriticConfig(actor_lr=0.05, critic_lr=0.1, gamma=0.9, value_lr=0.0, normalize_lr=normalize)
    agent = FourierActorCritic(n, LOW, HIGH, 5, cfg, seed=0)
    g = torch.Generator().manual_seed(0)
    agent.w[:] = torch.randn(n, 256, generator=g, dtype=torch.float64) * 0.1
    agent.theta[:] = torch.randn(n, 5, 256, generator=g, dtype=torch.float64) * 0.1
    obs, obs_next = torch.rand(n, 4, generator=g), torch.rand(n, 4, generator=g)
    agent.act(TensorDict({"observation": obs}, [n]))
    w0, theta0 = agent.w.clone(), agent.theta.clone().requires_grad_(True)
    action = torch.tensor([0, 3, 4])
    reward = torch.tensor([[1.0], [-2.0], [5.0]])
    terminated = torch.tensor([[False], [False], [True]])
    transition = TensorDict(
        {
            "observation": obs,
            "action": action,
            "next": {"observation": obs_next, "reward": reward, "terminated": terminated, "done": terminated},
        },
        [n],
    )
    root = TensorDict({"observation": obs_next}, [n])
    agent.step(transition, root)

    phi, phi_next = agent.features(obs), agent.features(obs_next)
    value, value_next = (w0 * phi).sum(-1), (w0 * phi_next).sum(-1) * (~terminated.squeeze(-1))
    delta = reward.squeeze(-1).double() + 0.9 * value_next - value
    scale = 1 / phi.norm(dim=-1) if normalize else torch.ones(n, dtype=torch.float64)
    log_pi = torch.log_softmax(torch.einsum("naf,nf->na", theta0, phi), -1)[torch.arange(n), action]
    log_pi.sum().backward()
    expected_theta = theta0.detach() + (0.05 * scale * delta)[:, None, None] * theta0.grad
    expected_w = w0 + (0.1 * scale * delta)[:, None] * phi
    assert torch.allclose(agent.theta, expected_theta, atol=1e-10)
    assert torch.allclose(agent.w, expected_w, atol=1e-10)


def test_same_seed_same_learning() -> None:
    def run() -> torch.Tensor:
        env = PinBallEnv(3, seed=2, max_steps=200)
        spec = env.observation_spec["observation"]
        agent = FourierActorCritic(3, spec.low[0], spec.high[0], 5, AC_PRESETS["released"], seed=4)
        return run_episodes(env, agent, 3).steps

    assert torch.equal(run(), run())


def _inverse_cdf(probs: torch.Tensor, u: np.ndarray) -> torch.Tensor:
    """The kernels' draw: the first action whose cumulative probability exceeds ``u``."""
    below = (probs.cumsum(-1)[:, :-1] <= torch.from_numpy(u)[:, None]).sum(-1)
    return below


@pytest.mark.parametrize("normalize", [False, True])
def test_q_actor_critic_update_matches_autograd(normalize: bool) -> None:
    """The authors' released agent: a' ~ π(·|s') first, actor step scaled by Q(s, a), SARSA critic per action."""

    n, cfg = (
        3,
        ActorCriticConfig(
            actor_lr=0.05, critic_lr=0.1, gamma=0.9, value_lr=0.0, normalize_lr=normalize, critic="action"
        ),
    )
    agent = FourierActorCritic(n, LOW, HIGH, 5, cfg, seed=0)
    assert agent.w.shape == (n, 5 * 256)
    g = torch.Generator().manual_seed(1)
    agent.w[:] = torch.randn(n, 5 * 256, generator=g, dtype=torch.float64) * 0.1
    agent.theta[:] = torch.randn(n, 5, 256, generator=g, dtype=torch.float64) * 0.1
    obs, obs_next, obs_reset = (torch.rand(n, 4, generator=g) for _ in range(3))
    agent.act(TensorDict({"observation": obs}, [n]))
    w0 = agent.w.clone().view(n, 5, 256)
    theta0 = agent.theta.clone().requires_grad_(True)
    action = torch.tensor([0, 3, 4])
    reward = torch.tensor([[1.0], [-2.0], [5.0]])
    terminated = torch.tensor([[False], [False], [True]])
    truncated = torch.tensor([[False], [True], [False]])
    transition = TensorDict(
        {
            "observation": obs,
            "action": action,
            "next": {
                "observation": obs_next,
                "reward": reward,
                "terminated": terminated,
                "done": terminated | truncated,
            },
        },
        [n],
    )
    root = TensorDict({"observation": torch.where(terminated | truncated, obs_reset, obs_next)}, [n])
    drawn = np.empty((n, 2))
    draw_uniforms(agent.streams.numpy().copy(), 2, drawn)  # each learner's next two draws
    u = np.concatenate([drawn[:, 0], drawn[:, 1]])  # a' for all, then the reset draws
    agent.step(transition, root)

    phi, phi_next, phi_reset = agent.features(obs), agent.features(obs_next), agent.features(obs_reset)
    with torch.no_grad():
        a_next = _inverse_cdf(torch.softmax(torch.einsum("naf,nf->na", theta0, phi_next), -1), u[:n])
    rows = torch.arange(n)
    q = (w0[rows, action] * phi).sum(-1)
    q_next = (w0[rows, a_next] * phi_next).sum(-1) * (~terminated.squeeze(-1))  # truncation bootstraps
    delta = reward.squeeze(-1).double() + 0.9 * q_next - q
    scale = 1 / phi.norm(dim=-1) if normalize else torch.ones(n, dtype=torch.float64)
    log_pi = torch.log_softmax(torch.einsum("naf,nf->na", theta0, phi), -1)[rows, action]
    log_pi.sum().backward()
    expected_theta = theta0.detach() + (0.05 * scale * q)[:, None, None] * theta0.grad
    expected_w = w0.clone()
    expected_w[rows, action] += (0.1 * scale * delta)[:, None] * phi
    assert torch.allclose(agent.theta, expected_theta, atol=1e-10)
    assert torch.allclose(agent.w, expected_w.reshape(n, -1), atol=1e-10)
    assert np.allclose(agent.q_values(obs)[rows, action].numpy(), (expected_w[rows, action] * phi).sum(-1).numpy())
    # the next action: a' where the episode goes on, a draw at the reset state (updated θ) where it ended
    reset_probs = torch.softmax(torch.einsum("naf,nf->na", expected_theta, phi_reset), -1)
    expected_action = torch.where((terminated | truncated).squeeze(-1), _inverse_cdf(reset_probs, u[n:]), a_next)
    assert torch.equal(root["action"], expected_action)
    assert torch.allclose(agent.phi, torch.where((terminated | truncated), phi_reset, phi_next))
