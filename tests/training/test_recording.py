"""What the learners record after every batch."""

from __future__ import annotations

import math

import torch
from tensordict import TensorDict
from torchrl.envs import TransformedEnv

from tests.line_env import LineEnv
from torchrl_subgoal import Box, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
from torchrl_subgoal.training.envs import EPISODE_RETURN
from torchrl_subgoal.training.recording import EpisodeWindow


def test_the_window_counts_the_subgoals_finished_episodes_reached() -> None:
    window = EpisodeWindow(2, cap=10.0, reward_scale=1.0)
    done = torch.tensor([[True], [False], [True]])
    data = TensorDict(
        {
            ("next", "done"): done,
            ("next", "terminated"): done,
            ("next", EPISODE_RETURN): torch.zeros(3, 1),
            ("next", "subgoal_index"): torch.tensor([[2], [1], [0]]),
        },
        [3],
    )
    window.add(data)
    assert window.subgoals_reached() == 1.0  # (2 + 0) / 2: the unfinished episode is not counted
    unshaped = EpisodeWindow(2, cap=10.0, reward_scale=1.0)
    unshaped.add(data.exclude(("next", "subgoal_index")))
    assert math.isnan(unshaped.subgoals_reached())


def test_a_shaped_rollout_reports_the_subgoals_its_episodes_reached() -> None:
    series = SubgoalSeries([Box((1.0,), (0.5,), (0,)), Box((3.0,), (0.5,), (0,))])
    env = TransformedEnv(LineEnv(2, length=4), SubgoalPotentialTransform(series, TabularPotential(3), gamma=0.9))
    data = env.rollout(4, policy=lambda td: td.set("action", torch.ones(2, dtype=torch.long)))
    data["next", EPISODE_RETURN] = torch.zeros(*data.batch_size, 1)
    window = EpisodeWindow(4, cap=10.0, reward_scale=1.0)
    window.add(data)
    assert window.count == 2 and window.subgoals_reached() == 2.0
