"""What a block returns: the trained modules, saved and reloaded in a fresh process to the same greedy return;
evaluation; the device every config names; learners with their own tasks in one env batch."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from torchrl_subgoal import Box, SubgoalSeries, TabularPotential
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.training import (
    DDPGTrainConfig,
    DQNConfig,
    PPOConfig,
    Shaping,
    SuccessSignal,
    evaluate,
    learner_envs,
    load_trained,
    train_ddpg,
    train_dqn,
    train_ppo,
)

from .corridor import continuous_corridor, discrete_corridor

ROOT = Path(__file__).resolve().parents[2]
GOAL = SuccessSignal(min_return=1.0)  # the corridor's reward of 1 at its end
SERIES = SubgoalSeries([Box((0.625,), (0.375,), (0,)), Box((0.75,), (0.25,), (0,))])

_RELOAD = """
import json, sys
from torchrl_subgoal.training import SuccessSignal, load_trained
from tests.training.corridor import continuous_corridor, discrete_corridor

path, env = sys.argv[1], {"discrete": discrete_corridor, "continuous": continuous_corridor}[sys.argv[2]]
trained = load_trained(path, env)
print(json.dumps([vars(trained.evaluate(env, 3, learner=k, success=SuccessSignal(min_return=1.0)))
                  for k in range(len(trained.seeds))]))
"""


def _reload(path: Path, kind: str) -> list[dict[str, list[float]]]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run(
        [sys.executable, "-c", _RELOAD, str(path), kind], capture_output=True, text=True, env=env, cwd=ROOT, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def test_a_trained_dqn_reloads_in_a_fresh_process_and_walks_the_corridor_as_before(tmp_path: Path) -> None:
    torch.set_num_threads(1)
    config = DQNConfig(
        num_envs=4,
        frames_per_batch=32,
        total_frames=3072,
        learning_starts=256,
        gradient_steps=8,
        batch_size=64,
        buffer_size=5000,
        lr=1e-3,
        gamma=0.95,
        exploration_frames=1536,
        target_update_interval=50,
        hidden=(32,),
    )
    trained = train_dqn(discrete_corridor, config, seeds=[0, 1], success=GOAL)
    here = [vars(trained.evaluate(discrete_corridor, 3, learner=k, success=GOAL)) for k in range(2)]
    assert here[0]["returns"] == [1.0, 1.0, 1.0] and here[0]["lengths"] == [8, 8, 8]  # the shortest path
    assert here[0]["success"] == [1.0, 1.0, 1.0]
    trained.save(tmp_path / "dqn.pt")
    assert _reload(tmp_path / "dqn.pt", "discrete") == here


def test_a_trained_ddpg_agent_reloads_with_its_normaliser(tmp_path: Path) -> None:
    config = DDPGTrainConfig(
        num_envs=2,
        frames_per_batch=32,
        total_frames=128,
        learning_starts=32,
        updates_per_batch=4,
        batch_size=16,
        hidden=(16,),
    )
    trained = train_ddpg(continuous_corridor, config, seeds=[0, 5])
    here = [vars(trained.evaluate(continuous_corridor, 3, learner=k, success=GOAL)) for k in range(2)]
    assert here[0] != here[1]  # two learners, two policies
    trained.save(tmp_path / "ddpg.pt")
    assert _reload(tmp_path / "ddpg.pt", "continuous") == here
    again = load_trained(tmp_path / "ddpg.pt", continuous_corridor)
    assert torch.equal(again.modules["agent"].norm.mean, trained.modules["agent"].norm.mean)
    assert repr(again.curves) == repr(trained.curves)  # (NaN: success not measured on the corridor)


def test_a_policy_that_reads_z_is_evaluated_with_its_learner_s_potential() -> None:
    config = PPOConfig(num_envs=2, frames_per_batch=32, minibatch_size=16, epochs=1, total_frames=64, sees_subgoal=True)
    shapings = [Shaping(SERIES, TabularPotential(3).freeze([0.0, 0.5, float(k)])) for k in range(2)]
    trained = train_ppo(discrete_corridor, config, seeds=[0, 1], shaping=shapings)
    assert trained.policy(1).in_keys == ["observation", "subgoal_index"]
    assert trained.potential(1).table.tolist() == [0.0, 0.5, 1.0]  # learner 1's own table
    result = trained.evaluate(discrete_corridor, 2, learner=1)
    assert len(result.returns) == 2 and all(0 < n <= 40 for n in result.lengths)


def test_evaluate_reports_success_only_where_it_is_measured() -> None:
    from tensordict.nn import TensorDictModule

    right = TensorDictModule(lambda o: torch.ones(o.shape[0], dtype=torch.long), ["observation"], ["action"])
    result = evaluate(right, discrete_corridor, 2)  # always right: the 8 steps to the end
    assert result.lengths == [8, 8] and result.returns == [1.0, 1.0]
    assert all(v != v for v in result.success)  # no success entry, no threshold: not measured (NaN)
    assert evaluate(right, discrete_corridor, 2, success=GOAL).success_rate == 1.0


def test_the_config_s_device_reaches_the_modules_and_the_replay() -> None:
    config = DQNConfig(num_envs=2, frames_per_batch=16, total_frames=32, learning_starts=16, gradient_steps=1,
                       batch_size=8, hidden=(8,), device="cpu")  # fmt: skip
    trained = train_dqn(discrete_corridor, config, seeds=[0, 1])
    assert {p.device for p in trained.modules["q"].parameters()} == {torch.device("cpu")}
    assert trained.config.device == "cpu" and {p.device.type for p in trained.policy(0).parameters()} == {"cpu"}


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal where there is no CUDA")
def test_a_device_that_is_not_there_is_refused_naming_it() -> None:
    config = DQNConfig(num_envs=2, frames_per_batch=16, total_frames=32, device="cuda")
    with pytest.raises(ValueError, match=r"^device 'cuda': CUDA is not available here"):
        train_dqn(discrete_corridor, config)


def test_learners_with_their_own_tasks_step_as_one_env_batch() -> None:
    """PointMaze's start and goal are each learner's own: their envs join into one env batch, learner-major."""
    from torchrl_subgoal.envs.point_maze import point_maze_env

    joined = learner_envs([point_maze_env("umaze", 0), point_maze_env("umaze", 1)])
    start = joined(4).reset()["observation"][:, :2].round()
    assert start.tolist() == [[-1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0], [-1.0, 1.0]]  # each learner's start cell
    assert learner_envs([FourRoomsEnv, FourRoomsEnv]) is FourRoomsEnv  # one task: the factory itself
    with pytest.raises(ValueError, match="join into one env batch"):
        learner_envs([FourRoomsEnv, discrete_corridor])
