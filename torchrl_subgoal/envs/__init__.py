"""Batched environments of the paper's domains (batch = independent learners)."""

from torchrl_subgoal.envs.four_rooms import FourRoomsEnv
from torchrl_subgoal.envs.pinball import PinBallEnv

__all__ = ["FourRoomsEnv", "PinBallEnv"]
