"""Tabular Q-learning on a Collector: it learns, and under a step cost the library's default potential
helps where the paper's mean target makes the shaped learner wander."""

from __future__ import annotations

import pytest
import torch
from torchrl.envs import TransformedEnv

from torchrl_subgoal import (
    State,
    SubgoalPotentialTransform,
    SubgoalSeries,
    SubgoalValueLoss,
    TabularPotential,
    ValueUpdate,
)
from torchrl_subgoal.training.qlearning import EpsilonGreedyQ, QLearningConfig, train_qlearning

from .penalty_grid import PenaltyGrid

GAMMA = 0.99
LEARNERS, EPISODES = 4, 80


def _shaped(grid: PenaltyGrid, **target: object) -> tuple[TransformedEnv, TabularPotential]:
    series = SubgoalSeries([State(grid.cell(3, 3)), State(grid.cell(6, 6))])
    potential = TabularPotential(series.num_abstract_states, (LEARNERS,))
    update = ValueUpdate(0.25, SubgoalValueLoss(potential, **target).make_value_estimator(gamma=GAMMA))  # type: ignore[arg-type]
    return TransformedEnv(
        grid, SubgoalPotentialTransform(series, potential, gamma=GAMMA, value_update=update)
    ), potential


def _success(env: TransformedEnv | PenaltyGrid) -> float:
    config = QLearningConfig(episodes=EPISODES, lr=0.25, epsilon=0.1, gamma=GAMMA)
    records = train_qlearning(env, config, seed=0).records  # success: the grid's own "success" entry
    return float(records.success[:, -20:].float().mean())


def test_under_a_step_cost_the_default_potential_keeps_the_unshaped_success_and_the_mean_target_does_not() -> None:
    """10×10 grid, −1 per step, −10 to idle, 200 steps, subgoals on the diagonal. Unshaped and with the
    library's default the learners succeed; with the mean target (time-outs bootstrapped) ``V(z_0)``
    learns the value of the early wandering (far below the optimal −16.5 of 18 steps), and
    ``(1 − γ)|Φ|`` then outweighs the step cost: wandering inside ``z`` pays."""
    torch.set_num_threads(1)
    unshaped = _success(PenaltyGrid(LEARNERS))
    env, default = _shaped(PenaltyGrid(LEARNERS))
    shaped = _success(env)
    env, mean = _shaped(PenaltyGrid(LEARNERS), expectile=0.5, bootstrap_truncated=True)
    wandering = _success(env)
    optimal = -(1 - GAMMA**18) / (1 - GAMMA)
    assert unshaped >= 0.9 and shaped >= 0.9
    assert wandering <= 0.7
    assert float(default.table.detach()[:, 0].mean()) == pytest.approx(optimal, abs=4.0)
    assert (1 - GAMMA) * float(
        mean.table.detach()[:, 0].mean()
    ) < -1.0  # within z_0, shaping pays more than a step costs


def test_epsilon_greedy_breaks_ties_at_random_and_reads_z() -> None:
    policy = EpsilonGreedyQ(
        1, states=2, actions=3, abstract_states=2, epsilon=0.0, generator=torch.Generator().manual_seed(0)
    )
    from tensordict import TensorDict

    td = TensorDict({"observation": torch.tensor([1]), "subgoal_index": torch.tensor([[1]])}, [1])
    seen = {int(policy(td.clone())["action"]) for _ in range(40)}
    assert seen == {0, 1, 2}
    policy.table[0, 1, 1, 2] = 1.0
    assert {int(policy(td.clone())["action"]) for _ in range(10)} == {2}
    policy.table[0, 1, 0, 0] = 5.0  # another z's entry: not read
    assert int(policy(td.clone())["action"]) == 2


def test_bad_settings_and_observations_are_refused() -> None:
    with pytest.raises(ValueError, match="epsilon"):
        QLearningConfig(epsilon=2.0)
    from torchrl_subgoal.envs import FourRoomsEnv

    with pytest.raises(ValueError, match="categorical observation 'cell'"):
        train_qlearning(FourRoomsEnv(2), QLearningConfig(episodes=1), observation_key="cell")


def test_an_episode_that_ends_in_a_hole_is_no_success() -> None:
    """FrozenLake ends an episode in a hole as in the goal; success is the goal's reward of 1, not the end."""
    import functools

    import gymnasium

    from torchrl_subgoal.envs.gym_batch import gym_batch
    from torchrl_subgoal.training import SuccessSignal

    env = gym_batch([functools.partial(gymnasium.make, "FrozenLake-v1", is_slippery=False)] * 8, max_steps=100)
    trained = train_qlearning(env, QLearningConfig(episodes=20, epsilon=1.0), success=SuccessSignal(final_reward=1.0))
    records = trained.records
    ended = records.steps < 100  # terminated: a hole or the goal
    assert bool(ended.all()) and bool(torch.equal(records.success, records.returns >= 1.0))
    assert 0 < int(records.success.sum()) < int(ended.sum())  # most random walks fall into a hole
    assert trained.policy(3).table.shape == (1, 16, 1, 4)
