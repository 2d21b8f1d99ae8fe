"""The learners by name: each entry trains with its own block, and the action check names what fits."""

from __future__ import annotations

import functools

import pytest
from torchrl.envs import GymEnv

from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.training import (
    LEARNERS,
    A2CConfig,
    DDPGTrainConfig,
    DQNConfig,
    PPOConfig,
    action_kind,
    batched,
    check_actions,
    train_a2c,
    train_ddpg,
    train_dqn,
    train_ppo,
)


def test_each_learner_is_its_building_block() -> None:
    assert [(n, lrn.config, lrn.train) for n, lrn in LEARNERS.items()] == [
        ("a2c", A2CConfig, train_a2c),
        ("ppo", PPOConfig, train_ppo),
        ("dqn", DQNConfig, train_dqn),
        ("ddpg", DDPGTrainConfig, train_ddpg),
    ]
    assert [lrn.title for lrn in LEARNERS.values()] == ["A2C", "PPO", "DQN", "DDPG"]


def test_action_kinds() -> None:
    assert action_kind(FourRoomsEnv(1)) == "discrete"
    assert action_kind(batched(functools.partial(GymEnv, "Pendulum-v1"))(1)) == "continuous"


@pytest.mark.parametrize("algo", ["a2c", "ppo", "dqn"])
def test_discrete_learners_accept_four_rooms(algo: str) -> None:
    check_actions(algo, FourRoomsEnv(1), "four_rooms")  # nothing raised


def test_a_mismatch_is_one_line_naming_what_fits() -> None:
    pendulum = batched(functools.partial(GymEnv, "Pendulum-v1"))(1)
    with pytest.raises(
        ValueError,
        match=r"^dqn needs discrete actions; pendulum's are continuous: choose ppo or "
        r"ddpg$",
    ):
        check_actions("dqn", pendulum, "pendulum")
    with pytest.raises(
        ValueError,
        match=r"^ddpg needs continuous actions; four_rooms's are discrete: choose a2c, "
        r"ppo or dqn$",
    ):
        check_actions("ddpg", FourRoomsEnv(1), "four_rooms")
    with pytest.raises(ValueError, match=r"^unknown learner 'sac'; known: a2c, ppo, dqn, ddpg$"):
        check_actions("sac", FourRoomsEnv(1), "four_rooms")
