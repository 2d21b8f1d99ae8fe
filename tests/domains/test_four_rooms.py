"""The four-rooms domains' learner set-ups: the DQN defaults learn the task and keep it; the step-cost variant."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from torchrl_subgoal import domains, load_patterns
from torchrl_subgoal.experiments.paper import PaperResults
from torchrl_subgoal.subgoals import SubgoalFileError, patterns_from_data
from torchrl_subgoal.training import LearnerDomain, train_dqn


@pytest.mark.slow
def test_dqn_defaults_find_the_shortest_path_and_keep_it() -> None:
    """With a biased output layer or Adam at 1e-2 the Q-table's greedy policy found the path, then lost it
    for tens of thousands of frames once ε was small (episodes back at the 1,000-step cap)."""
    torch.set_num_threads(1)
    domain = domains.part("four_rooms", LearnerDomain)
    config = dataclasses.replace(domain.defaults["dqn"], total_frames=60_160)
    curve = train_dqn(domain.make_env, config).curve
    found = curve.frames_to(50)
    assert found is not None and found < 40_000
    after = [length for frames, length in zip(curve.frames, curve.episode_length, strict=True) if frames > found]
    assert max(after) < 120 and curve.episode_length[-1] < 25


def test_the_step_cost_variant_is_a_domain_of_its_own() -> None:
    """``four_rooms_step``: the same map, subgoals and learner set-ups under −1 per step, A2C given 300,032
    frames and DQN's rewards scaled by 0.01; a subgoal file is checked against the four-rooms map."""
    goal = domains.part("four_rooms", LearnerDomain)
    step = domains.part("four_rooms_step", LearnerDomain)
    assert domains.get("four_rooms_step").part(PaperResults) is None  # the paper did not run it
    rewards = step.make_env(2).rollout(5)["next", "reward"]
    assert torch.equal(rewards, torch.full_like(rewards, -1.0))
    assert (step.participants, step.thresholds, step.subgoal_key) == (goal.participants, goal.thresholds, "cell")
    assert step.defaults["a2c"] == dataclasses.replace(goal.defaults["a2c"], total_frames=300_032)
    assert step.defaults["ppo"] == goal.defaults["ppo"]
    assert step.defaults["dqn"] == dataclasses.replace(goal.defaults["dqn"], reward_scale=0.01)
    assert len(load_patterns(step.participants, domain="four_rooms_step")) == 10
    with pytest.raises(SubgoalFileError, match="is a wall"):
        patterns_from_data(
            {"patterns": {"p": {"subgoals": [{"cell": [0, 6]}]}}},
            "mine.yaml",
            check=domains.subgoal_check("four_rooms_step"),
        )


def test_the_recipe_runs_on_the_step_cost_variant(tmp_path) -> None:
    from torchrl_subgoal.experiments.learners import (
        LearnerRecipeConfig,
        default_learner,
        learner_plan,
        run_learner_chunk,
    )
    from torchrl_subgoal.experiments.store import Chunk

    a2c = default_learner("a2c", domains.part("four_rooms_step", LearnerDomain), {"total_frames": 512})
    cfg = LearnerRecipeConfig(domain="four_rooms_step", methods="A2C,NRS", learner=a2c, results=str(tmp_path))
    plan = learner_plan(cfg, "a2c")
    assert plan.config["domain"] == "four_rooms_step" and plan.config["learner"]["total_frames"] == 512
    for spec in plan.specs:
        table = run_learner_chunk(Chunk(spec.name, 0, ((spec.patterns[0], 0),), seed=1), plan.config, lambda n: None)
        assert (table.n_learners, table.n_episodes) == (1, 2)
