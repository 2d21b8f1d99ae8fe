"""A2C building blocks: networks, the shaped env, the training loop."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from torchrl_subgoal import Cell, NaivePotential, State, SubgoalSeries, TabularPotential, domains
from torchrl_subgoal.domains.four_rooms import four_rooms_env
from torchrl_subgoal.envs import PinBallEnv
from torchrl_subgoal.fused._kernels.actor_critic import _feature_scratch, fourier_features
from torchrl_subgoal.training import (
    A2CConfig,
    A2CDomain,
    FourierFeatures,
    LearnerDomain,
    Shaping,
    actor_critic,
    experiment_logger,
    shaped_env,
    train_a2c,
)

from ..line_env import LineEnv

HALLWAYS = SubgoalSeries([Cell(3, 6), Cell(7, 9)])


def test_fourier_features_equal_the_fused_kernels() -> None:
    low, high = torch.tensor([0.0, 0.0, -2.0, -2.0]), torch.tensor([1.0, 1.0, 2.0, 2.0])
    basis = FourierFeatures(low, high, order=3)
    obs = torch.rand(5, 4) * (high - low) + low
    ours = basis(obs)
    scratch, ref = _feature_scratch(3, 2, 4, 256)
    for b in range(5):
        fourier_features(
            obs[b].double().numpy(), low.double().numpy(), (1 / (high - low)).double().numpy(), 3, 2, scratch, ref
        )
        assert np.allclose(ours[b].numpy(), ref, atol=1e-5)


@pytest.mark.parametrize("domain", ["four_rooms", "pinball"])
def test_actor_critic_for_each_domain(domain: str) -> None:
    d = domains.part(domain, A2CDomain)
    env = d.make_env(3)
    actor, critic = actor_critic(env, d.observation_key, features=d.a2c.features, hidden=(8,))
    td = critic(actor(env.reset()))
    assert td["action"].shape == (3,) and td["state_value"].shape == (3, 1)
    assert torch.allclose(td["logits"], torch.zeros_like(td["logits"]))  # a uniform policy at the start


def test_shaped_env_in_env_workers_keeps_the_potential_in_this_process() -> None:
    potential = TabularPotential(3)
    with torch.no_grad():
        potential.table.copy_(torch.tensor([0.0, 1.0, 2.0]))
    shaping = Shaping(SubgoalSeries([Cell(1, 2)]), potential, {"observation_key": "cell"})
    env = shaped_env(four_rooms_env, 4, env_workers=2, shaping=shaping, gamma=0.9)
    try:
        data = env.rollout(40, break_when_any_done=False)
    finally:
        env.close()
    assert data.batch_size == (2, 2, 40)
    nxt = data["next"]
    table = potential.table.detach()
    expected = (
        nxt["env_reward"]
        + 0.9 * table[nxt["subgoal_index"]].masked_fill(nxt["terminated"], 0)
        - table[data["subgoal_index"]]
    )
    assert torch.allclose(nxt["reward"], expected) and (nxt["subgoal_index"] > 0).any()


def test_a2c_learns_four_rooms_and_trains_the_potential(tmp_path: Path) -> None:
    torch.set_num_threads(1)
    potential = TabularPotential(3)
    shaping = Shaping(HALLWAYS, potential, {"observation_key": "cell"})
    config = A2CConfig(features="one_hot", hidden=(), lr=1e-2, total_frames=40_960, online_potential=False)
    logger = experiment_logger(tmp_path, "HRS_test")
    curve = train_a2c(four_rooms_env, config, shaping=shaping, seeds=[0], loggers=[logger]).curve
    assert len(curve.frames) == config.iterations == 160 and curve.frames[-1] == 40_960
    assert curve.episode_length[0] == 1000.0  # the cap until an episode finished
    assert curve.episodes[-1] > 100 and min(curve.episode_length) < 150  # it learns
    assert bool((potential.table.detach() > 0).all())  # V(z) learned from the goal reward
    logged = list(tmp_path.rglob("*.csv"))
    assert any(p.name.startswith("episode_length") for p in logged)
    assert any(p.name.startswith("loss_potential") for p in logged)


def test_the_default_trains_the_potential_online_and_logs_its_table(tmp_path: Path) -> None:
    """By default the transform trains ``V(z)`` (no per-batch loss); the logger gets the table after every batch."""
    torch.set_num_threads(1)
    potential = TabularPotential(3)
    shaping = Shaping(HALLWAYS, potential, {"observation_key": "cell"})
    config = A2CConfig(features="one_hot", hidden=(), lr=1e-2, total_frames=20_480)
    assert config.online_potential
    train_a2c(four_rooms_env, config, shaping=shaping, seeds=[0], loggers=[experiment_logger(tmp_path, "HRS_online")])
    logged = {p.stem: p for p in tmp_path.rglob("*.csv")}
    assert "loss_potential" not in logged
    last = [float(logged[f"potential_z{z}"].read_text().split()[-1].split(",")[-1]) for z in range(3)]
    assert last == pytest.approx(potential.table.detach().tolist())
    assert any(v != 0.0 for v in last)  # the goal was reached: a closed transition moved the table


@pytest.mark.parametrize("workers", [{"collector_workers": 1}, {"env_workers": 2, "num_envs": 4}])
@pytest.mark.parametrize("online", [False, True])
def test_a2c_with_envs_in_worker_processes(online: bool, workers: dict[str, int]) -> None:
    """Envs in worker processes (a MultiSyncCollector's, or a ParallelEnv's); the potential trained in the main
    process (or online in the workers, into the main process's table)."""
    potential = TabularPotential(3)
    shaping = Shaping(SubgoalSeries([State(1), State(3)]), potential)
    config = A2CConfig(
        features="one_hot", hidden=(), total_frames=2048, online_potential=online, value_lr=0.1, **workers
    )
    curve = train_a2c(lambda n: LineEnv(n, length=4), config, shaping=shaping, seeds=[1], episode_cap=100).curve
    assert len(curve.frames) == 8
    assert curve.episodes[-1] > 0 and bool((potential.table.detach() > 0.5).all())


@pytest.mark.parametrize("workers", [{"collector_workers": 1}, {"env_workers": 2, "num_envs": 4}])
def test_a_prior_weights_counts_reach_the_main_process_from_worker_processes(workers: dict[str, int]) -> None:
    """``Shaping(prior_weight=k)``: the workers' transforms count each entry's updates into the shared
    potential's ``updates`` buffer (the step sizes they give are tested in tests/test_transform.py), so the
    main process sees them; without a prior weight nothing is counted."""
    for weight in (2.0, 0.0):
        potential = TabularPotential(3)
        shaping = Shaping(SubgoalSeries([State(1), State(3)]), potential, prior_weight=weight)
        config = A2CConfig(features="one_hot", hidden=(), total_frames=1024, value_lr=0.01, **workers)
        train_a2c(lambda n: LineEnv(n, length=4), config, shaping=shaping, seeds=[1], episode_cap=100)
        assert bool((potential.updates > 0).all()) == (weight > 0)  # with a weight, every z closed transitions
        assert bool((potential.table.detach() != 0).all())  # trained online in the workers, either way


@pytest.mark.parametrize("workers", [{"collector_workers": 1}, {"env_workers": 2, "num_envs": 4}])
def test_a_frozen_potential_stays_frozen_in_worker_processes(workers: dict[str, int]) -> None:
    """The set-up above, whose online update moves the shared table, with the table frozen: the workers'
    transforms shape with it and leave it as it was."""
    potential = TabularPotential(3).freeze([0.25, 0.5, 0.75])
    shaping = Shaping(SubgoalSeries([State(1), State(3)]), potential)
    config = A2CConfig(features="one_hot", hidden=(), total_frames=2048, value_lr=0.1, **workers)
    curve = train_a2c(lambda n: LineEnv(n, length=4), config, shaping=shaping, seeds=[1], episode_cap=100).curve
    assert curve.episodes[-1] > 0 and potential.table.tolist() == [0.25, 0.5, 0.75]


def test_a2c_with_two_collector_workers_takes_a_sweep_seed() -> None:
    """Sweep seeds take 63 bits; a worker seeds numpy with the collector's seed, which takes 32. A batch
    holds frames_per_batch frames of both workers: as many batches as ``iterations`` says."""
    config = A2CConfig(
        features="one_hot", hidden=(), num_envs=4, frames_per_batch=64, total_frames=256, collector_workers=2
    )
    curve = train_a2c(lambda n: LineEnv(n, length=4), config, seeds=[2**62 + 5], episode_cap=100).curve
    assert len(curve.frames) == config.iterations == 4
    assert curve.frames == [64, 128, 192, 256]
    with pytest.raises(ValueError, match=r"multiple of num_envs x collector_workers \(4 x 3\)"):
        A2CConfig(num_envs=4, frames_per_batch=64, collector_workers=3)


_EXITS_AFTER_CLOSE = """
import functools
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.training import A2CConfig, actor_critic, close_collector, make_collector

if __name__ == "__main__":
    config = A2CConfig(num_envs=2, frames_per_batch=16, total_frames=32, collector_workers=2)
    actor, _ = actor_critic(FourRoomsEnv(2), features="one_hot")
    collector = make_collector(functools.partial(FourRoomsEnv, 2), actor, config)
    print(sum(batch.numel() for batch in collector))
    close_collector(collector)
"""


def test_a_process_exits_after_close_collector(tmp_path: Path) -> None:
    """A MultiSyncCollector with a policy leaves weight-sync schemes behind its shutdown; closed with
    close_collector, the process exits (with collector.shutdown() alone it hung at interpreter exit)."""
    script = tmp_path / "collect.py"
    script.write_text(_EXITS_AFTER_CLOSE)
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")]))}
    # the timeout only ends a hang (the script takes seconds); a hang is the failure
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split()[-1] == "32"


def test_naive_potential_is_not_trained() -> None:
    shaping = Shaping(HALLWAYS, NaivePotential(1.0), {"observation_key": "cell"})
    assert not shaping.trained
    curve = train_a2c(four_rooms_env, A2CConfig(features="one_hot", hidden=(), total_frames=512), shaping=shaping).curve
    assert len(curve.frames) == 2


def test_without_an_entropy_bonus_the_losses_log_zero_entropy(tmp_path: Path) -> None:
    """TorchRL's A2CLoss writes no entropy loss without an entropy bonus; a batch of learners still trains."""
    config = A2CConfig(features="one_hot", hidden=(), total_frames=512, entropy_coeff=0.0)
    loggers = [experiment_logger(tmp_path, f"A2C_{seed}") for seed in (0, 1)]
    trained = train_a2c(four_rooms_env, config, seeds=[0, 1], loggers=loggers)
    assert [len(curve.frames) for curve in trained.curves] == [2, 2]
    for logged in tmp_path.rglob("loss_entropy.csv"):
        assert [float(line.split(",")[-1]) for line in logged.read_text().split()] == [0.0, 0.0]
    assert len(list(tmp_path.rglob("loss_entropy.csv"))) == 2


@pytest.mark.parametrize("bad", [{"num_envs": 0}, {"frames_per_batch": 100}, {"env_workers": 3}, {"features": "cnn"}])
def test_bad_settings(bad: dict) -> None:
    with pytest.raises(ValueError):
        A2CConfig(**bad)


def test_a2c_domains_come_from_the_registry() -> None:
    assert A2CDomain is LearnerDomain  # the earlier name still finds the part
    assert domains.part("four_rooms", A2CDomain).name == "four_rooms"
    assert domains.part("pinball", A2CDomain).a2c.features == "fourier"
    with pytest.raises(
        ValueError,
        match=r"^unknown domain 'chess'; the domains with a LearnerDomain: acrobot, four_rooms, four_rooms_step, ",
    ):
        domains.part("chess", A2CDomain)
    with pytest.raises(
        ValueError,
        match=r"^domain 'pick_and_place' registered no LearnerDomain; the domains that did: acrobot, four_rooms, ",
    ):
        domains.part("pick_and_place", A2CDomain)


def test_pinball_env_factory_is_seeded_from_torch() -> None:
    d = domains.part("pinball", A2CDomain)
    rollouts = []
    for _ in range(2):
        torch.manual_seed(0)
        env = d.make_env(2)
        assert isinstance(env, PinBallEnv)
        torch.manual_seed(1)
        rollouts.append(env.rollout(30)["next", "observation"])
    assert torch.equal(*rollouts)


def test_pinball_default_step_is_the_papers_divided_by_the_feature_norm() -> None:
    """PinBall A2C's Adam rate is the paper's 0.01 over ``‖φ‖`` on visited states (0.01 itself was unstable)."""
    d = domains.part("pinball", A2CDomain)
    torch.manual_seed(0)
    env = d.make_env(8)
    obs = env.rollout(200, break_when_any_done=False)["observation"].reshape(-1, 4)
    spec = env.observation_spec["observation"].space
    norm = FourierFeatures(spec.low[0], spec.high[0], d.a2c.fourier_order)(obs).norm(dim=-1).mean()
    assert d.a2c.lr == pytest.approx(0.01 / float(norm), rel=0.15)


def test_train_a2c_on_a_single_env_batched_by_serial_env() -> None:
    """The documented path for a user's unbatched env: ``batched(make_single)`` (a SerialEnv,
    which is closed until started: the probe env used to raise on close)."""
    from torchrl.envs import GymEnv

    from torchrl_subgoal.training import batched

    def make_single() -> GymEnv:
        return GymEnv("CliffWalking-v1", categorical_action_encoding=True)

    series = SubgoalSeries([State(24)])
    shaping = Shaping(series, TabularPotential(2), {"observation_key": "observation"})
    config = A2CConfig(num_envs=2, frames_per_batch=32, total_frames=64, features="one_hot", hidden=())
    curve = train_a2c(batched(make_single), config, shaping=shaping, seeds=[0], episode_cap=100).curve
    assert curve.frames == [32, 64]


def test_a2c_learners_as_a_batch_each_learn_with_their_own_table(tmp_path: Path) -> None:
    """Three A2C learners as one batch: each learns four-rooms, trains its own table online from its own envs,
    and logs its own curve and table."""
    torch.set_num_threads(1)
    shapings = [Shaping(HALLWAYS, TabularPotential(3), {"observation_key": "cell"}) for _ in range(3)]
    config = A2CConfig(features="one_hot", hidden=(), lr=1e-2, total_frames=40_960)
    ticks: list[int] = []
    loggers = [experiment_logger(tmp_path, f"HRS_{k}") for k in range(3)]
    curves = train_a2c(
        four_rooms_env, config, seeds=[0, 1, 2], shaping=shapings, loggers=loggers, progress=ticks.append
    ).curves
    assert len(ticks) == 3 * config.iterations
    for k, curve in enumerate(curves):
        assert curve.frames[-1] == 40_960 and len(curve.frames) == config.iterations
        assert curve.episodes[-1] > 100 and min(curve.episode_length) < 150  # each learns
        table = shapings[k].potential.table.detach()
        assert torch.equal(table, torch.zeros(3))  # the learner's own potential is copied, not trained
        logged = float((tmp_path / f"HRS_{k}" / "scalars" / "potential_z2.csv").read_text().split()[-1].split(",")[-1])
        assert logged > 0  # its batch table learned from the goal reward
    assert len({c.episode_length[-1] for c in curves} | {tuple(c.episodes) for c in curves}) > 1


@pytest.mark.parametrize(
    ("settings", "match"),
    [
        ({"collector_workers": 1}, "collector_workers 0"),
        ({"online_potential": False}, "online_potential must be True"),
    ],
)
def test_a2c_learner_batch_refuses_settings_it_has_no_per_learner_version_of(settings: dict, match: str) -> None:
    config = A2CConfig(features="one_hot", hidden=(), total_frames=512, **settings)
    shapings = [Shaping(HALLWAYS, TabularPotential(3), {"observation_key": "cell"}) for _ in range(2)]
    with pytest.raises(ValueError, match=match):
        train_a2c(four_rooms_env, config, seeds=[0, 1], shaping=shapings)


@pytest.mark.parametrize(
    ("sees", "actor_keys", "critic_keys"),
    [
        ("critic", ["observation"], ["observation", "subgoal_index"]),
        (True, ["observation", "subgoal_index"], ["observation", "subgoal_index"]),
        (False, ["observation"], ["observation"]),
    ],
)
def test_by_default_a_shaped_critic_reads_z_and_the_policy_does_not(
    sees: bool | str, actor_keys: list[str], critic_keys: list[str]
) -> None:
    """The shaped return depends on z; the policy keeps the unshaped learner's inputs."""
    from torchrl_subgoal.envs import FourRoomsEnv
    from torchrl_subgoal.training import actor_critic_modules, subgoal_states

    config = A2CConfig(features="one_hot", sees_subgoal=sees)
    states = subgoal_states(config, Shaping(HALLWAYS, TabularPotential(3)))
    modules = actor_critic_modules(FourRoomsEnv(1), config, subgoal_states=states, seeds=[0, 1])
    assert modules["actor"].in_keys == actor_keys and modules["critic"].in_keys == critic_keys
    assert subgoal_states(A2CConfig(), None) == 0  # unshaped: nothing to read
