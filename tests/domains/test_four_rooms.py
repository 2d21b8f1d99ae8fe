"""The four-rooms domain's learner set-up: its DQN defaults learn the task and keep it."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from torchrl_subgoal import domains
from torchrl_subgoal.training import LearnerDomain, train_dqn


@pytest.mark.slow
def test_dqn_defaults_find_the_shortest_path_and_keep_it() -> None:
    """With a biased output layer or Adam at 1e-2 the Q-table's greedy policy found the path, then lost it
    for tens of thousands of frames once ε was small (episodes back at the 1,000-step cap)."""
    torch.set_num_threads(1)
    domain = domains.part("four_rooms", LearnerDomain)
    config = dataclasses.replace(domain.defaults["dqn"], total_frames=60_160)
    curve = train_dqn(domain.make_env, config, seed=0)
    found = curve.frames_to(50)
    assert found is not None and found < 40_000
    after = [length for frames, length in zip(curve.frames, curve.episode_length, strict=True) if frames > found]
    assert max(after) < 120 and curve.episode_length[-1] < 25
