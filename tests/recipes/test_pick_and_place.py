"""Pick and place: the neural potential's SMDP step, V shared with env and collector workers, the recipe,
resume (in this process and with collector workers)."""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict
from torch import nn
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.data import Bounded
from torchrl.envs import ParallelEnv, TransformedEnv

from tests.recipes.test_recipes import recipe
from torchrl_subgoal import (
    NeuralPotential,
    SubgoalKeys,
    SubgoalPotentialTransform,
    SubgoalValueLoss,
    TabularPotential,
)
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.experiments import load_frame
from torchrl_subgoal.experiments.cli import ConfigError, parse_config
from torchrl_subgoal.training import DDPGTrainConfig, EnvFactory, batched, close_collector, shaped_env
from torchrl_subgoal.training.ddpg_parts import DDPGAgent, DDPGConfig

GAMMA = 0.98


def fetch_env(num_envs: int, potential: NeuralPotential, parallel: bool):
    make = partial(fetch.make_fetch_env, 5)
    base = ParallelEnv(num_envs, make) if parallel else make()
    series = fetch.human_patterns()["participants"]
    # Φ = V (not the library's default "nonpositive" level), to compare F with V directly
    return TransformedEnv(
        base,
        SubgoalPotentialTransform(
            series, potential, gamma=GAMMA, start_potential="value", keys=SubgoalKeys(transitions="smdp")
        ),
    )


def test_neural_potential_step_matches_the_smdp_target() -> None:
    torch.manual_seed(0)
    potential = NeuralPotential(nn.Linear(fetch.OBSERVATION_SIZE, 1))
    env = fetch_env(1, potential, parallel=False)
    data = env.rollout(50, break_when_any_done=False)  # one time-out: one SMDP transition
    smdp = data["next", "smdp"]
    emitted = smdp[smdp["mask"].squeeze(-1)]
    assert emitted.shape == (1,) and emitted["steps_to_next_obs"].item() == 50
    assert emitted["next", "reward"].item() == pytest.approx(-(1 - GAMMA**50) / (1 - GAMMA), rel=1e-5)
    # by hand: δ = r_h + γ^k V(o') − V(o), and SGD on ½δ² moves w by α δ o, b by α δ
    lr = 1e-3
    w, b = potential.network.weight.detach().clone(), potential.network.bias.detach().clone()
    anchor, next_anchor = emitted["subgoal_anchor"], emitted["next", "subgoal_anchor"]
    delta = emitted["next", "reward"] + GAMMA**50 * (next_anchor @ w.T + b) - (anchor @ w.T + b)
    pick_and_place = recipe("pick_and_place")
    trainer = pick_and_place.PotentialTrainer(
        env.transform,
        # the recipe's (the paper's) target: the mean, a time-out bootstrapped
        SubgoalValueLoss(potential, reduction="mean", expectile=0.5, bootstrap_truncated=True).make_value_estimator(
            gamma=GAMMA
        ),
        torch.optim.SGD(potential.parameters(), lr=lr),
    )
    trainer.step(data)
    assert torch.allclose(potential.network.weight, w + lr * delta * anchor, atol=1e-6)
    assert torch.allclose(potential.network.bias, b + lr * delta.flatten(), atol=1e-6)


def test_parallel_env_shapes_with_the_potential_the_loss_trains() -> None:
    pick_and_place = recipe("pick_and_place")
    torch.manual_seed(0)
    potential = NeuralPotential(nn.Linear(fetch.OBSERVATION_SIZE, 1))
    env = fetch_env(2, potential, parallel=True)
    transform = env.transform
    loss = SubgoalValueLoss(
        transform.potential, reduction="mean", expectile=0.5, bootstrap_truncated=True
    ).make_value_estimator(gamma=GAMMA)  # the recipe's target: the time-outs train V
    trainer = pick_and_place.PotentialTrainer(transform, loss, torch.optim.Adam(loss.potential.parameters(), lr=0.1))
    collector = Collector(env, None, frames_per_batch=100, total_frames=200, auto_register_policy_transforms=False)
    batches = iter(collector)
    before = potential.network.weight.detach().clone()
    trainer.step(next(batches))  # both envs timed out: V moves
    after = potential.network.weight.detach().clone()
    data = next(batches)
    collector.shutdown()
    assert loss.potential is transform.potential is potential
    # the next batch was shaped in this process with the trained V: F = γ V(o_z') − V(o_z)
    with torch.no_grad():
        phi = potential(data["subgoal_anchor"])
        phi_next = potential(data["next", "subgoal_anchor"])
    shaping = data["next", "reward"] - data["next", "env_reward"]
    assert torch.allclose(shaping, GAMMA * phi_next - phi, atol=1e-4)
    assert not torch.equal(after, before)


def test_collector_workers_shape_with_the_trained_potential_and_act_with_the_trained_policy() -> None:
    """A MultiSyncCollector's 2 workers (1 env each) read V from shared memory: every batch is shaped
    with V as trained here after the previous batch (the workers wait while this process trains: no
    staleness), and act with the policy as updated here (``update_policy_weights_``)."""
    pick_and_place = recipe("pick_and_place")
    torch.manual_seed(0)
    config = {"eta": 0.1, "shaping": {"start_potential": "value"}, "value_lr": 0.1, "ddpg": {"hidden": (8,)}}
    shaping, trainer = pick_and_place.make_shaping("HRS", fetch.human_patterns()["participants"], config, GAMMA)
    agent = DDPGAgent(
        fetch.OBSERVATION_SIZE, fetch.make_fetch_env(5).action_spec_unbatched, DDPGConfig(hidden=(8,), batch_size=16)
    )
    factory = EnvFactory(
        shaped_env,
        make_env=batched(partial(fetch.make_fetch_env, 5)),
        num_envs=1,
        shaping=shaping,
        potential=shaping.potential,
        gamma=GAMMA,
    )
    collector = MultiSyncCollector(
        [factory] * 2,
        agent.greedy,
        frames_per_batch=100,
        total_frames=-1,
        cat_results="stack",
        auto_register_policy_transforms=False,
    )
    batches = iter(collector)
    for _ in range(2):
        data = next(batches)
        before = [p.detach().clone() for p in shaping.potential.parameters()]
        trainer.step(data)  # both workers' episodes timed out: V moves
        assert any(not torch.equal(a, b) for a, b in zip(before, shaping.potential.parameters(), strict=True))
        agent.extend(data)
        agent.update()
        collector.update_policy_weights_()
        data = next(batches)
        with torch.no_grad():  # F = γ V(o_z') − V(o_z) with this process's V, trained before the batch
            phi = shaping.potential(data["subgoal_anchor"])
            phi_next = shaping.potential(data["next", "subgoal_anchor"])
            greedy = agent.greedy(data.select("observation").clone())["action"]
        shaped = data["next", "reward"] - data["next", "env_reward"]
        assert torch.allclose(shaped, GAMMA * phi_next - phi, atol=1e-5)
        assert torch.allclose(data["action"], greedy, atol=1e-5)
    close_collector(collector)


TINY = ["--preset", "tiny", "--learnings", "1", "--num-envs", "1", "--collector-workers", "0", "--workers", "0"]


def test_recipe_all_methods_and_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pick_and_place = recipe("pick_and_place")
    args = [*TINY, "--epochs", "1", "--methods", "DDPG,HRS,RRS,NRS,SARSA-RS,HRS-D,SRS", "--results", str(tmp_path)]
    assert pick_and_place.main(args) == 0
    out = capsys.readouterr().out
    assert "| 0.6 | HRS |" in out and "| HRS | 0 (—) | 0 [0, 0] | 0.67 |" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["metric"] == "success" and summary["unit"] == "epoch"
    assert not summary["lower_is_better"]
    assert set(summary["methods"]) == {"DDPG", "HRS", "RRS", "NRS", "SARSA-RS", "HRS-D", "SRS"}
    frame = load_frame(tmp_path)
    assert (frame["steps"] == 200).all() and frame["return"].between(-50.0, 0.0).all()


@pytest.mark.parametrize(
    "processes",
    [
        [],
        ["--num-envs", "2", "--collector-workers", "2"],  # MuJoCo, policy noise and shaping in 2 worker processes
    ],
    ids=["in-process", "collector-workers"],
)
def test_kill_and_resume_equals_an_uninterrupted_learning(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, processes: list[str]
) -> None:
    pick_and_place = recipe("pick_and_place")
    args = [*TINY, "--epochs", "3", "--methods", "HRS", *processes]
    assert pick_and_place.main([*args, "--results", str(tmp_path / "whole")]) == 0

    evaluate, calls = pick_and_place.evaluate, []

    def crash_in_second_epoch(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt  # as a kill: mid-epoch 2, after epoch 1's checkpoint
        return evaluate(*a, **k)

    monkeypatch.setattr(pick_and_place, "evaluate", crash_in_second_epoch)
    # the recipes turn Ctrl-C into "interrupted: ... run the same command again", exit 130
    assert pick_and_place.main([*args, "--results", str(tmp_path / "resumed")]) == 130
    state = torch.load(tmp_path / "resumed" / "checkpoints" / "HRS" / "00000" / "state.pt", weights_only=False)
    assert state["epoch"] == 1
    monkeypatch.setattr(pick_and_place, "evaluate", evaluate)
    assert pick_and_place.main([*args, "--results", str(tmp_path / "resumed")]) == 0

    assert load_frame(tmp_path / "whole").equals(load_frame(tmp_path / "resumed"))
    whole, resumed = (
        torch.load(tmp_path / d / "checkpoints" / "HRS" / "00000" / "state.pt", weights_only=False)
        for d in ("whole", "resumed")
    )
    for part in ("agent", "potential"):
        a, b = (whole[part]["modules"], resumed[part]["modules"]) if part == "agent" else (whole[part], resumed[part])
        assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_bad_settings_name_the_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pick_and_place = recipe("pick_and_place")
    assert pick_and_place.main(["--num-envs", "4", "--results", str(tmp_path)]) == 2
    assert (
        "--num-envs: a cycle's 300 steps must split into whole 50-step episodes over 4 envs" in capsys.readouterr().err
    )
    assert pick_and_place.main(["--shaping", "{bad", "--results", str(tmp_path)]) == 2
    assert "--shaping: not valid JSON" in capsys.readouterr().err
    assert pick_and_place.main(["--num-envs", "6", "--collector-workers", "4", "--results", str(tmp_path)]) == 2
    assert (
        "--num-envs: 6 envs do not split evenly over --collector-workers 4 x --env-workers 0" in capsys.readouterr().err
    )


def test_a_pattern_rrs_cannot_randomise_is_one_line_naming_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a first pattern over gripper velocities: a valid file, but RRS has no range to draw its centres from
    path = tmp_path / "velocities.yaml"
    path.write_text(
        "format: torchrl_subgoal/v1\npatterns:\n  moving:\n    subgoals:\n"
        "    - box: {centre: [0, 0, 0], margin: 0.01, slice: [20, 23]}\n"
    )
    pick_and_place = recipe("pick_and_place")
    assert pick_and_place.main(["--subgoals", str(path), "--results", str(tmp_path / "out")]) == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]  # (gymnasium-robotics may warn on import before it)
    assert last.startswith(f"error: {path}: pattern 'moving': RRS has no range")
    assert "'gripper_velocity'" in last and not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("mode", "unshaped", "shaped"), [("unshaped", True, False), ("all", True, True), ("none", False, False)]
)
def test_clip_positive_chooses_whose_targets_are_clipped_above(
    tmp_path: Path, mode: str, unshaped: bool, shaped: bool
) -> None:
    pick_and_place = recipe("pick_and_place")
    cfg = parse_config(pick_and_place.Config, ["--clip-positive", mode, "--results", str(tmp_path)])
    config = pick_and_place.plan(cfg).config
    assert pick_and_place.agent_config(config, shaped=False).clip_positive is unshaped
    assert pick_and_place.agent_config(config, shaped=True).clip_positive is shaped
    # a configuration stored before the setting existed clips every learner as it did
    old = {k: v for k, v in config.items() if k != "shaped_clip_positive"}
    assert pick_and_place.agent_config(old, shaped=True).clip_positive is unshaped


def shaped_targets(agent: DDPGAgent) -> list[float]:
    """TD targets of a failed and a successful step in z_0 once Φ(z_0) = −1/(1 − γ): shaped rewards
    −1 + (γ − 1)Φ = 0 and 0 + (γ − 1)Φ = 1, with a critic that learned Q ≡ 0 (the run's learned state)."""
    phi = -1 / (1 - agent.config.gamma)
    rewards = torch.tensor([[-1.0], [0.0]]) + (agent.config.gamma - 1) * phi
    for net in (agent.loss.target_value_network_params, agent.loss.value_network_params):
        net.apply(lambda p: p.data.zero_())  # Q ≡ 0
    obs = torch.zeros(2, fetch.OBSERVATION_SIZE)
    batch = TensorDict(
        {
            "observation": obs,
            "action": torch.zeros(2, 4),
            "next": {
                "observation": obs,
                "reward": rewards,
                "done": torch.zeros(2, 1, dtype=torch.bool),
                "terminated": torch.zeros(2, 1, dtype=torch.bool),
            },
        },
        [2],
    )
    batch.set("observation_normalized", agent.norm(obs))
    batch.set(("next", "observation_normalized"), agent.norm(obs))
    return agent.loss.loss_value(batch)[1]["target_value"].tolist()


def test_shaped_learner_tells_success_from_failure_only_with_the_top_open(tmp_path: Path) -> None:
    # measured in the HRS learnings (docs/pick_and_place.md): V(z_0) = −50 after 3 epochs
    pick_and_place = recipe("pick_and_place")
    config = pick_and_place.plan(parse_config(pick_and_place.Config, ["--results", str(tmp_path)])).config
    spec = Bounded(-1.0, 1.0, shape=(4,))
    small = {**config, "ddpg": {**config["ddpg"], "hidden": [8]}}
    clipped = DDPGAgent(
        fetch.OBSERVATION_SIZE, spec, pick_and_place.agent_config({**small, "shaped_clip_positive": True}, shaped=True)
    )
    assert shaped_targets(clipped) == [0.0, 0.0]  # the authors' clip: success and failure look the same
    default = DDPGAgent(fetch.OBSERVATION_SIZE, spec, pick_and_place.agent_config(small, shaped=True))
    assert shaped_targets(default) == pytest.approx([0.0, 1.0])


def test_hrs_and_rrs_start_at_zero_potential_unless_told() -> None:
    """``--start-potential`` (default ``zero``: Φ(z_0) = 0, the authors' level) sets HRS's and RRS's transform,
    not NRS's; ``--shaping``'s JSON wins; the stored configuration records it (a resumed run keeps its level)."""
    pick_and_place = recipe("pick_and_place")
    series = fetch.human_patterns()["participants"]
    cfg = parse_config(pick_and_place.Config, ["--preset", "tiny", "--learnings", "1"])
    config = pick_and_place.plan(cfg).config
    assert config["start_potential"] == "zero"

    def level(method: str, config: dict) -> str:
        shaping, _ = pick_and_place.make_shaping(method, series, config, GAMMA)
        return shaping.transform(shaping.potential, GAMMA, None).start_potential

    assert level("HRS", config) == level("RRS", config) == "zero"
    assert level("NRS", config) == "nonpositive"  # a NaivePotential: Φ(z_0) = 0 whatever the level
    chosen = pick_and_place.plan(parse_config(pick_and_place.Config, ["--start-potential", "nonpositive"])).config
    assert level("HRS", chosen) == "nonpositive"
    assert level("HRS", {**config, "shaping": {"start_potential": "value"}}) == "value"


def test_the_librarys_potentials_are_tables_learned_online_with_the_librarys_target() -> None:
    """HRS-D is the library's default (the progress prior, interpolating within segments, monotone, level
    ``nonpositive``), learned online at the training blocks' step with the library's target; SRS is the
    prior, fixed; SARSA-RS's table keeps the library's target too: only the neural potentials (HRS, RRS)
    learn the paper's mean, a time-out bootstrapped."""
    pick_and_place = recipe("pick_and_place")
    series = fetch.human_patterns()["participants"]
    cfg = parse_config(
        pick_and_place.Config, ["--preset", "tiny", "--methods", "HRS-D,SRS,DDPG", "--progress-scale", "3"]
    )
    config = pick_and_place.plan(cfg).config
    assert config["progress_scale"] == 3.0
    shaping, trainer = pick_and_place.make_shaping("HRS-D", series, config, GAMMA)
    assert trainer is None and isinstance(shaping.potential, TabularPotential)
    assert shaping.potential.table.tolist() == pytest.approx([0.0, 1.0, 2.0])  # the prior, 3 / (2 + 1) a subgoal
    assert shaping.potential.interpolate and shaping.potential.monotone
    settings = pick_and_place.learner_config(config, "HRS-D", shaped=True, epochs=1)
    assert settings.online_potential and settings.value_lr == DDPGTrainConfig.value_lr
    transform = shaping.transform(shaping.potential, GAMMA, settings.value_lr)
    assert transform.start_potential == "nonpositive" and transform.learning
    assert transform.value_update.loss.expectile == SubgoalValueLoss(shaping.potential).expectile
    assert not transform.value_update.loss.bootstrap_truncated
    fixed, _ = pick_and_place.make_shaping("SRS", series, config, GAMMA)
    assert not fixed.trained and fixed.potential.table.tolist() == pytest.approx([0.0, 1.0, 2.0])
    table, _ = pick_and_place.make_shaping("SARSA-RS", None, config, GAMMA)
    online = table.transform(table.potential, GAMMA, config["aggregation_lr"]).value_update
    assert online.lr == config["aggregation_lr"] and not online.loss.bootstrap_truncated
    neural, neural_trainer = pick_and_place.make_shaping("HRS", series, config, GAMMA)
    assert neural_trainer is not None and neural.loss == pick_and_place.NEURAL_TARGET
    # a run without HRS-D or SRS stores no progress_scale, so that its results resume as before
    assert "progress_scale" not in pick_and_place.plan(parse_config(pick_and_place.Config, ["--preset", "tiny"])).config
    with pytest.raises(ConfigError, match="--progress-scale: what reaching the goal is worth must be > 0"):
        parse_config(pick_and_place.Config, ["--progress-scale", "0"])
