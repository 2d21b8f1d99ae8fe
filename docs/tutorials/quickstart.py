"""Quick start: a shaped A2C learner on gymnasium's CliffWalking, beside an unshaped one.

python docs/tutorials/quickstart.py      # ~2 min of CPU; TUTORIAL_TINY=1: seconds (what CI runs)
"""

import os

import torch
from torchrl.envs import GymEnv

from torchrl_subgoal import State, SubgoalSeries, TabularPotential
from torchrl_subgoal.training import A2CConfig, Shaping, batched, train_a2c


def make_single() -> GymEnv:  # your env: any TorchRL env (here a gymnasium one, 4 x 12 cells)
    return GymEnv("CliffWalking-v1", categorical_action_encoding=True)


def past_halfway(td):  # a subgoal can be any function of the step's TensorDict
    cell = td["observation"]
    return (cell // 12 <= 2) & (cell % 12 >= 6)


if __name__ == "__main__":
    torch.set_num_threads(1)
    # leave the start upwards (cell 24), go right past the middle, stand above the goal (cell 35)
    series = SubgoalSeries([State(24), past_halfway, State(35)])
    # the default potential: starts at a progress prior over the subgoals, learned online as the learner collects
    shaping = Shaping(series, TabularPotential.for_subgoals(series), {"observation_key": "observation"})
    frames = 2_048 if os.environ.get("TUTORIAL_TINY") else 40_000
    config = A2CConfig(
        num_envs=8,
        frames_per_batch=128,
        total_frames=frames,
        features="one_hot",
        hidden=(),
        lr=0.05,
        value_lr=0.1,
        online_potential=True,
    )
    for name, arm in (("unshaped", None), ("shaped", shaping)):
        curve = train_a2c(batched(make_single), config, shaping=arm, seeds=[0], episode_cap=5000).curve
        print(
            f"{name}: {curve.episodes[-1]} episodes, mean length of the last ones {curve.episode_length[-1]:.0f} "
            f"steps (the shortest path takes 13)"
        )
