"""Batched softmax SARSA and the episode loop."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs import TransformedEnv

from torchrl_subgoal import Cell, SubgoalSeries
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.fused import SARSA_PRESETS, SarsaConfig, SoftmaxSarsa, run_episodes
from torchrl_subgoal.methods import paper_methods, shaping_transform


def test_update_rule_by_hand() -> None:
    cfg = SarsaConfig(lr=0.5, gamma=0.9, temperature=1.0, value_lr=0.0)
    agent = SoftmaxSarsa(2, num_states=3, num_actions=2, config=cfg)
    agent.q[:] = torch.tensor([[[0.0, 1.0], [2.0, 3.0], [4.0, 5.0]], [[0.5, 0.5], [1.0, 1.0], [6.0, 6.0]]])
    # learner 0: s=0,a=1 -> s'=1, r=1, goes on; learner 1: s=1,a=0 -> s'=2, r=2, terminated
    transition = TensorDict(
        {
            "observation": torch.tensor([0, 1]),
            "action": torch.tensor([1, 0]),
            "next": {
                "observation": torch.tensor([1, 2]),
                "reward": torch.tensor([[1.0], [2.0]]),
                "terminated": torch.tensor([[False], [True]]),
                "done": torch.tensor([[False], [True]]),
            },
        },
        batch_size=[2],
    )
    root = TensorDict({"observation": torch.tensor([1, 0])}, batch_size=[2])
    before = agent.q.clone()
    agent.step(transition, root)
    a2 = int(root["action"][0])  # learner 0 continues with a' ~ π(·|s'), sampled in step
    expected0 = 1.0 + 0.5 * (1.0 + 0.9 * float(before[0, 1, a2]) - 1.0)
    assert agent.q[0, 0, 1].item() == pytest.approx(expected0)
    assert agent.q[1, 1, 0].item() == pytest.approx(1.0 + 0.5 * (2.0 - 1.0))  # no bootstrap at termination
    changed = (agent.q != before).sum().item()
    assert changed == 2


def test_softmax_follows_the_temperature() -> None:
    cfg = SarsaConfig(lr=0.1, gamma=0.9, temperature=0.5, value_lr=0.0)
    agent = SoftmaxSarsa(20_000, 1, 3, cfg, seed=0)
    agent.q[:, 0] = torch.tensor([0.0, 0.5, 1.0])
    freq = torch.bincount(agent.sample(torch.zeros(20_000, dtype=torch.long)), minlength=3) / 20_000
    expected = torch.softmax(torch.tensor([0.0, 0.5, 1.0]) / 0.5, 0)
    assert torch.allclose(freq, expected, atol=0.015)


def test_same_seed_same_results() -> None:
    def run(seed: int) -> torch.Tensor:
        env = FourRoomsEnv(6)
        agent = SoftmaxSarsa(6, env.num_states, 4, SARSA_PRESETS["released"], seed=seed)
        return run_episodes(env, agent, 4).steps

    assert torch.equal(run(1), run(1))
    assert not torch.equal(run(1), run(2))


def test_loop_records_every_episode() -> None:
    env = FourRoomsEnv(5, max_steps=50)
    agent = SoftmaxSarsa(5, env.num_states, 4, SARSA_PRESETS["released"])
    finished: list[int] = []
    rec = run_episodes(env, agent, 3, progress=finished.append)
    assert rec.steps.shape == (5, 3) and sum(finished) == 15
    assert ((rec.steps >= 20) & (rec.steps <= 50)).all()
    assert torch.equal(rec.success, rec.returns == 1.0)  # reward 1 exactly when the goal is reached
    assert torch.equal(rec.success, rec.steps < 50) or (rec.steps == 50).any()


@pytest.mark.parametrize("method", ["HRS", "SARSA-RS"])
def test_learned_potential_does_not_change_the_optimum(method: str) -> None:
    """Shaping must not change the optimum (Ng et al. 1999).

    The potential is learned by the method as usual (300 episodes) from two
    participants' series (one on each 20-step route), then frozen; a fresh
    learner trained on the fixed shaped reward must take the 20-step shortest
    path. The theorem needs Φ to be a function of the agent's state, so the HRS
    learner sees ``(s, z)``. Invariance concerns the optimum only: shaping acts
    like an initialisation of Q (Wiewiora 2003), and with subgoals *off* every
    shortest route a τ = 0.01 softmax learner can settle on the detour they
    suggest (measured in docs/four_rooms.md).
    """
    from torchrl_subgoal.envs.four_rooms import room_aggregation

    n = 8
    cfg = SARSA_PRESETS["released"]
    patterns = [SubgoalSeries([Cell(4, 9), Cell(11, 9)]), SubgoalSeries([Cell(5, 2), Cell(10, 5)])]
    shaping = shaping_transform(
        paper_methods("SARSA")[method],
        torch.Size([n]),
        gamma=cfg.gamma,
        value_lr=cfg.value_lr,
        patterns=patterns,
        pattern_index=torch.arange(n) % 2,
        aggregation=room_aggregation(),
        observation_key="cell",
    )
    assert shaping is not None
    env = TransformedEnv(FourRoomsEnv(n), shaping)
    z_states = 3 if method == "HRS" else 1

    def learner(seed: int) -> SoftmaxSarsa:
        return SoftmaxSarsa(n, 104, 4, cfg, seed=seed, abstract_states=z_states)

    run_episodes(env, learner(0), 300)  # learns the potential
    shaping.potential.requires_grad_(False)
    learned = shaping.potential.table.detach().clone()
    assert (learned[:, 0] > 0).all()
    agent = learner(1)
    records = run_episodes(env, agent, 300)
    assert torch.equal(shaping.potential.table.detach(), learned)  # stayed frozen
    assert records.success[:, -50:].all()

    env.base_env.max_steps = 100  # greedy evaluation; the transform still tracks z
    td = env.reset()
    lengths = torch.zeros(n, dtype=torch.long)
    running = torch.ones(n, dtype=torch.bool)
    for _ in range(100):
        td["action"] = agent.greedy(agent.state(td))
        td = env.step(td)["next"]
        lengths += running.long()
        running &= ~td["done"].squeeze(-1)
    # softmax SARSA (τ = 0.01) sometimes settles on a two-step detour: one or two learners of eight
    # did for most seeds, before learners had their own random streams too; most take the shortest path
    shortest = FourRoomsEnv().shortest_path_length()
    assert (lengths == shortest).sum() >= n - 2 and (lengths <= shortest + 4).all(), lengths.tolist()
