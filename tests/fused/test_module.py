"""Learners are ``nn.Module``s: their tables and streams checkpoint, move and cast through torch."""

from __future__ import annotations

import io

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torch import nn

from torchrl_subgoal.envs import FourRoomsEnv, PinBallEnv
from torchrl_subgoal.fused import (
    AC_PRESETS,
    SARSA_PRESETS,
    FourierActorCritic,
    SoftmaxSarsa,
    run_episodes,
)
from torchrl_subgoal.fused.module import KernelLearner

AC_STATE = ["w", "theta", "phi", "probs", "streams"]


def _four_rooms() -> FourRoomsEnv:
    return FourRoomsEnv(4, max_steps=200, goal_reward=0.0, step_reward=-1.0)  # rewards on every step


def _sarsa(seed: int) -> tuple[FourRoomsEnv, SoftmaxSarsa]:
    env = _four_rooms()
    return env, SoftmaxSarsa(4, env.num_states, 4, SARSA_PRESETS["released"], seed=seed)


def _pinball_env() -> PinBallEnv:
    return PinBallEnv(3, seed=1, max_steps=60, step_penalty=-1.0, thrust_penalty=-5.0)  # rewards on every step


def _pinball(seed: int, preset: str = "released") -> tuple[PinBallEnv, FourierActorCritic]:
    env = _pinball_env()
    spec = env.observation_spec["observation"]
    return env, FourierActorCritic(3, spec.low[0], spec.high[0], 5, AC_PRESETS[preset], seed=seed)


def _through_torch(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """``torch.save`` then ``torch.load``, as a checkpoint file would."""
    buffer = io.BytesIO()
    torch.save(state, buffer)
    buffer.seek(0)
    return torch.load(buffer, weights_only=True)


def test_learners_are_modules_with_their_state_in_buffers() -> None:
    _, sarsa = _sarsa(0)
    _, ac = _pinball(0)
    assert isinstance(sarsa, nn.Module) and isinstance(ac, nn.Module)
    assert list(sarsa.state_dict()) == ["q", "streams"] and list(ac.state_dict()) == AC_STATE
    assert not list(sarsa.parameters()) and not list(ac.parameters())  # nothing for autograd
    assert ac.w.dtype == ac.theta.dtype == torch.float64 and sarsa.q.dtype == torch.float32
    assert sarsa.streams.dtype == ac.streams.dtype == torch.uint64


@pytest.mark.parametrize("engine", ["torchrl", "fused"])
def test_sarsa_state_dict_round_trip_continues_identically(engine: str) -> None:
    env, agent = _sarsa(3)
    run_episodes(env, agent, 4, engine=engine)
    saved = _through_torch(agent.state_dict())
    _, clone = _sarsa(99)  # another seed: everything that matters must come from the checkpoint
    clone.load_state_dict(saved)
    assert torch.equal(clone.q, agent.q) and torch.equal(clone.streams, agent.streams)
    first = run_episodes(_four_rooms(), agent, 5, engine=engine)
    second = run_episodes(_four_rooms(), clone, 5, engine=engine)
    assert torch.equal(first.steps, second.steps) and torch.equal(first.returns, second.returns)
    assert torch.equal(agent.q, clone.q) and torch.equal(agent.streams, clone.streams)
    assert not torch.equal(agent.q, saved["q"])  # it went on learning


@pytest.mark.parametrize("preset", ["released", "paper"])
def test_actor_critic_state_dict_round_trip_continues_identically(preset: str) -> None:
    env, agent = _pinball(3, preset)
    run_episodes(env, agent, 2)
    saved = _through_torch(agent.state_dict())
    _, clone = _pinball(99, preset)
    clone.load_state_dict(saved)
    first = run_episodes(_pinball_env(), agent, 2)
    second = run_episodes(_pinball_env(), clone, 2)
    assert torch.equal(first.steps, second.steps) and torch.equal(first.returns, second.returns)
    for name in AC_STATE:
        assert torch.equal(getattr(agent, name), getattr(clone, name)), name
    assert not torch.equal(agent.theta, saved["theta"])


def test_loading_writes_into_the_kernels_memory() -> None:
    """A numpy view taken before ``load_state_dict`` sees the loaded tables: loading copies in place."""
    _, agent = _pinball(0)
    views = {name: agent.numpy_view(name) for name in AC_STATE}
    state = {name: torch.ones_like(value) for name, value in agent.state_dict().items()}
    agent.load_state_dict(state)
    for name, view in views.items():
        assert np.shares_memory(view, agent.numpy_view(name)) and (view == 1).all(), name


def test_kernel_state_is_views_of_the_buffers() -> None:
    _, sarsa = _sarsa(0)
    _, ac = _pinball(0)
    state = sarsa.kernel_state()
    assert np.shares_memory(state.q, sarsa.q.numpy()) and np.shares_memory(state.streams, sarsa.streams.numpy())
    assert state.q.dtype == np.float32 and state.streams.dtype == np.uint64
    ac_state = ac.kernel_state()
    for name in AC_STATE:
        assert np.shares_memory(getattr(ac_state, name), getattr(ac, name).numpy()), name
    ac.load_state_dict({name: torch.full_like(value, 2) for name, value in ac.state_dict().items()})
    assert (ac_state.theta == 2).all() and (ac_state.streams == 2).all()  # loaded into the kernels' memory


def test_kernels_update_the_buffers_through_their_views() -> None:
    env, agent = _sarsa(0)
    view, streams = agent.numpy_view("q"), agent.numpy_view("streams")
    assert np.shares_memory(view, agent.q.numpy()) and np.shares_memory(streams, agent.streams.numpy())
    before = streams.copy()
    run_episodes(env, agent, 1)
    assert view.any() and (streams != before).any()  # the kernels wrote into the buffers' memory


def test_cast_changes_the_tables_not_the_streams() -> None:
    _, ac = _pinball(0)
    ac.theta.normal_()
    theta, streams, view = ac.theta.clone(), ac.streams.clone(), ac.numpy_view("theta")
    assert ac.to("cpu") is ac and np.shares_memory(view, ac.numpy_view("theta"))  # already there: same memory
    ac.to(torch.float32)
    assert ac.theta.dtype == ac.w.dtype == ac.phi.dtype == ac.probs.dtype == torch.float32
    assert torch.equal(ac.theta, theta.float()) and torch.equal(ac.streams, streams)
    ac.half()  # nn.Module's own method: no attribute of the learner shadows it
    assert ac.theta.dtype == torch.float16
    ac.to(torch.float64)
    assert ac.theta.dtype == torch.float64 and ac.streams.dtype == torch.uint64


def test_sarsa_learns_in_float64_after_a_cast() -> None:
    env, agent = _sarsa(0)
    agent.to(torch.float64)
    run_episodes(env, agent, 2)
    assert agent.q.dtype == torch.float64 and agent.q.abs().sum() > 0


def test_a_learner_off_the_cpu_says_how_to_move_it_back() -> None:
    _, agent = _sarsa(0)
    agent.to("meta")
    assert agent.q.device.type == "meta"
    with pytest.raises(RuntimeError, match=r"^SoftmaxSarsa\.q is on meta.*\.to\('cpu'\)"):
        agent.act(TensorDict({"observation": torch.zeros(4, dtype=torch.long)}, [4]))


def test_calling_the_module_acts() -> None:
    _, agent = _pinball(0)
    td = agent(TensorDict({"observation": torch.full((3, 4), 0.5)}, [3]))
    assert td["action"].shape == (3,) and isinstance(agent, KernelLearner)
