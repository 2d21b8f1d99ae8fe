"""Single-goal FetchPickAndPlace: fixed per seed, the participants' boxes, RRS, SARSA-RS, install errors."""

from __future__ import annotations

from importlib import metadata

import pytest
import torch
from tensordict import TensorDict

from torchrl_subgoal.envs import fetch
from torchrl_subgoal.subgoals import SubgoalTables


@pytest.fixture(scope="module")
def env_seed_3():
    env = fetch.make_fetch_env(goal_seed=3)
    yield env
    env.close()


def test_goal_and_object_fixed_per_seed_different_across_seeds(env_seed_3) -> None:
    first = env_seed_3.reset()["observation"]
    env_seed_3.rollout(7)  # move the arm, then reset again: the same start
    again = env_seed_3.reset()["observation"]
    assert torch.equal(first, again)
    same = fetch.make_fetch_env(goal_seed=3)
    same.set_seed(12345)  # a caller's seed does not change the task
    assert torch.equal(same.reset()["observation"], first)
    goal = same._env.get_wrapper_attr("goal").copy()
    other = fetch.make_fetch_env(goal_seed=4)
    object_position = fetch.COMPONENTS["object_position"]
    assert not torch.equal(other.reset()["observation"][object_position], first[object_position])
    assert (other._env.get_wrapper_attr("goal") != goal).any()
    same.close(), other.close()


def test_observation_reward_and_episode(env_seed_3) -> None:
    rollout = env_seed_3.rollout(60)  # stops at the 50-step time-out
    assert rollout.shape == (50,)
    assert rollout["observation"].dtype == torch.float32
    assert rollout["observation"].shape == (50, fetch.OBSERVATION_SIZE)
    assert set(rollout["next", "reward"].unique().tolist()) <= {-1.0, 0.0}
    assert rollout["next", "truncated"][-1].item() and not rollout["next", "terminated"].any()
    assert rollout["next", "is_success"].dtype == torch.bool
    # reward 0 exactly when the object is at the goal
    assert torch.equal(rollout["next", "reward"] == 0, rollout["next", "is_success"])


def _observations(rows: list[dict[str, list[float]]]) -> torch.Tensor:
    obs = torch.full((len(rows), fetch.OBSERVATION_SIZE), 0.5)
    for i, row in enumerate(rows):
        for name, values in row.items():
            obs[i, fetch.COMPONENTS[name]] = torch.tensor(values)
    return obs


def test_participants_boxes_on_hand_made_observations() -> None:
    series = fetch.human_patterns()["participants"]
    rel, fingers = "object_relative_position", "finger_joints"
    obs = _observations(
        [
            {rel: [0.009, -0.009, 0.0], fingers: [0.04, 0.04]},  # gripper at the object (inside ±0.01)
            {rel: [0.011, 0.0, 0.0], fingers: [0.02, 0.02]},  # 0.011 off in x: not at the object
            {rel: [0.0, 0.0, 0.005], fingers: [0.025, 0.015]},  # at the object, fingers closed on it
            {rel: [0.0, 0.0, 0.005], fingers: [0.035, 0.02]},  # one finger 0.015 open: not grasped
        ]
    )
    tables = SubgoalTables([series], torch.zeros(4, dtype=torch.long), fetch.OBSERVATION_SIZE)
    assert tables.inside(obs).tolist() == [[True, False], [False, False], [True, True], [True, False]]
    # in order: from z = 0 only the first box counts, from z = 1 only the second
    z0, z1 = torch.zeros(4, 1, dtype=torch.long), torch.ones(4, 1, dtype=torch.long)
    assert tables.advance(z0, obs).flatten().tolist() == [1, 0, 1, 1]
    assert tables.advance(z1, obs).flatten().tolist() == [1, 1, 2, 1]
    assert torch.equal(tables.advance_eager(z1, obs), tables.advance(z1, obs))


def test_random_patterns_reproducible_over_the_same_components() -> None:
    human = fetch.human_patterns()["participants"]
    a = fetch.random_patterns(human, 3, seed=0)
    assert a == fetch.random_patterns(human, 3, seed=0)
    assert a != fetch.random_patterns(human, 3, seed=1)
    assert len({p.predicates for p in a}) == 3
    for pattern in a:
        for mine, theirs in zip(pattern.predicates, human.predicates, strict=True):
            assert mine.box_dims == theirs.box_dims and mine.margin == theirs.margin
            fingers = [c for d, c in zip(mine.box_dims, mine.centre, strict=True) if d in (9, 10)]
            assert all(0.0 <= c <= 0.05 for c in fingers)


def test_missing_extra_names_the_install_command(monkeypatch: pytest.MonkeyPatch) -> None:
    import builtins

    real_import = builtins.__import__

    def no_robotics(name: str, *args, **kwargs):
        if name == "gymnasium_robotics":
            raise ImportError("No module named 'gymnasium_robotics'", name="gymnasium_robotics")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_robotics)
    with pytest.raises(fetch.FetchUnavailableError, match=r"gymnasium_robotics is missing.*torchrl_subgoal\[fetch\]"):
        fetch.require_fetch()


def test_mujoco_312_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    real = metadata.version
    monkeypatch.setattr(fetch.metadata, "version", lambda name: "3.12.0" if name == "mujoco" else real(name))
    with pytest.raises(fetch.FetchUnavailableError, match=r"mujoco 3.12.0 is installed.*<3.12"):
        fetch.require_fetch()


@pytest.mark.parametrize("lean", [True, False], ids=["lean-step", "gymnasium-step"])
def test_batched_envs_equal_a_serial_env_of_single_envs(lean: bool) -> None:
    """``make_fetch_envs`` is the task of ``SerialEnv(make_fetch_env)``: same specs, bitwise the same
    data for the same actions, through time-outs and the collectors' partial resets."""
    from functools import partial

    from torchrl.envs.utils import check_env_specs

    from torchrl_subgoal.training import batched

    serial = batched(partial(fetch.make_fetch_env, 5))(3)
    envs = fetch.make_fetch_envs(5, 3, lean=lean)
    assert (envs.lean_steps is not None) == lean
    check_env_specs(envs)
    assert envs.full_observation_spec == serial.full_observation_spec
    assert envs.full_done_spec == serial.full_done_spec and envs.action_spec == serial.action_spec
    actions = torch.rand(120, 3, 4, generator=torch.Generator().manual_seed(0)) * 2 - 1

    def roll(env) -> TensorDict:  # type: ignore[no-untyped-def]
        td, steps = env.reset(), []
        for t in range(120):  # 2.4 episodes: two time-outs and their resets
            td["action"] = actions[t]
            full, td = env.step_and_maybe_reset(td)
            steps.append(full.clone())
        return torch.stack(steps, 1)

    a, b = roll(serial), roll(envs)
    assert set(a.keys(True, True)) == set(b.keys(True, True))
    for key in a.keys(True, True):
        assert torch.equal(a[key], b[key]), key
    assert b["next", "truncated"].sum() == 6
    serial.close()
    envs.close()


@pytest.mark.parametrize("goal_seed", [3, 11])
def test_lean_step_is_gymnasium_robotics_step_bit_for_bit(goal_seed: int) -> None:
    """``LeanStep`` against gymnasium's own step on a twin env: random actions (beyond the bounds, so
    the clip acts) over 4 episodes with resets; the goal moved near the object each episode so both
    rewards occur. Equal bit for bit: the float64 observation, the float32 one the agent sees, reward,
    success, the time-out, and MuJoCo's state after every step (so every later step is equal too)."""
    import numpy as np

    gymnasium = fetch.require_fetch()
    reference, twin = (gymnasium.make(fetch.ENV_ID, goal_seed=goal_seed) for _ in range(2))
    lean = fetch.LeanStep(twin)
    rng = np.random.default_rng(goal_seed)
    out = np.empty(fetch.OBSERVATION_SIZE)
    rewards, successes = set(), set()
    for _ in range(4):
        first, _ = reference.reset()
        assert np.array_equal(first, twin.reset()[0])
        lean.reset()
        offset = rng.uniform(-0.06, 0.06, 3)  # within 0.05 of the object's start or not
        for env in (reference, twin):
            task = env.unwrapped
            task.goal = task.data.site_xpos[lean.object].copy() + offset
        for t in range(fetch.MAX_EPISODE_STEPS):
            action = rng.uniform(-1.5, 1.5, 4).astype(np.float32)
            obs, reward, terminated, truncated, info = reference.step(action)
            lean_reward, lean_success, lean_truncated = lean.step(action, out)
            assert np.array_equal(reference.unwrapped._get_obs()["observation"], out), t
            assert obs.dtype == np.float32 and np.array_equal(obs, out.astype(np.float32))
            assert (reward, bool(info["is_success"][0]), truncated) == (lean_reward, lean_success, lean_truncated)
            assert not terminated and truncated == (t == fetch.MAX_EPISODE_STEPS - 1)
            a, b = reference.unwrapped.data, twin.unwrapped.data
            for name in ("time", "qpos", "qvel", "act", "ctrl", "mocap_pos", "mocap_quat", "qacc_warmstart"):
                assert np.array_equal(getattr(a, name), getattr(b, name)), (t, name)
            rewards.add(reward)
            successes.add(lean_success)
    assert rewards == {-1.0, 0.0} and successes == {True, False}
    reference.close(), twin.close()


def test_lean_step_refuses_what_it_does_not_replicate() -> None:
    gymnasium = fetch.require_fetch()
    env = gymnasium.make(fetch.ENV_ID, goal_seed=0)
    env.unwrapped.block_gripper = True
    with pytest.raises(ValueError, match=r"FetchPickAndPlace only.*block_gripper"):
        fetch.LeanStep(env)
    env.close()
