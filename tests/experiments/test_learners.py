"""The learner recipes' machinery: settings from the domain's defaults and the flags, the methods' names,
and the plan's stored configuration."""

from __future__ import annotations

import dataclasses
import json

import pytest

from torchrl_subgoal import domains, load_patterns
from torchrl_subgoal.experiments.cli import ConfigError, parse_config
from torchrl_subgoal.experiments.learners import (
    LearnerRecipeConfig,
    default_learner,
    learner_methods,
    learner_plan,
    learner_settings,
)
from torchrl_subgoal.recipes.train import Config as TrainConfig
from torchrl_subgoal.training import DQNConfig, LearnerDomain, PPOConfig


def recipe_config(algo: str = "a2c", domain: str = "four_rooms", **changes: object) -> LearnerRecipeConfig:
    """A learner recipe's settings with the domain's defaults for ``algo`` and ``changes`` to them."""
    learner = default_learner(algo, domains.part(domain, LearnerDomain), changes.pop("learner", None))  # type: ignore[arg-type]
    return LearnerRecipeConfig(domain=domain, learner=learner, **changes)  # type: ignore[arg-type]


def test_the_learners_flags_default_to_the_domains_settings() -> None:
    """Every field of the learner's settings is a flag whose default is the domain's (the preset's)."""
    mountain_car = domains.part("mountain_car", LearnerDomain)
    assert learner_settings(LearnerRecipeConfig(domain="mountain_car"), "dqn", mountain_car) == DQNConfig.preset(
        "mountain_car"
    )
    args = ["--algo", "dqn", "--domain", "mountain_car", "--total-frames", "3200", "--lr", "1e-3"]
    changed = parse_config(TrainConfig, [*args, "--sees-subgoal", "False", "--reshape-samples", "--hidden", "32", "32"])
    settings = changed.learner
    assert (settings.total_frames, settings.lr, settings.sees_subgoal, settings.hidden) == (3200, 1e-3, False, (32, 32))
    assert settings.reshape_samples and settings.gradient_steps == 8  # the preset's, untouched
    ppo = parse_config(TrainConfig, ["--algo", "ppo", "--domain", "pinball", "--clip-epsilon", "0.1"]).learner
    assert isinstance(ppo, PPOConfig) and ppo.clip_epsilon == 0.1 and ppo.features == "fourier"  # pinball's


def test_the_help_lists_the_learners_settings_and_choices_once(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        parse_config(TrainConfig, ["--algo", "dqn", "--domain", "mountain_car", "--help"], prog="torchrl-subgoal train")
    out = capsys.readouterr().out
    assert exit_.value.code == 0
    assert "{a2c,ppo,dqn,ddpg}" in out and "{csv,tensorboard,wandb,none}" in out  # choices, not a metavar
    assert "--gradient-steps" in out and "--clip-epsilon" not in out  # DQN's own settings
    assert "(default: 0.004)" in " ".join(out.split())  # mountain_car's DQN learning rate (wrapped anywhere)
    methods = out[out.index("--methods") : out.index("--learnings")]
    assert methods.count("(default:") == 1 and "theunshapedlearner,HRS-D,NRS" in "".join(methods.split())


def test_a_learner_without_defaults_for_the_domain_takes_its_own() -> None:
    umaze = domains.part("point_maze_umaze", LearnerDomain)
    assert "a2c" not in umaze.defaults
    assert learner_settings(LearnerRecipeConfig(), "a2c", umaze).frames_per_batch == 256  # A2CConfig's


def test_a_setting_the_learner_refuses_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"^--minibatch-size: minibatch_size \(64\) must divide frames_per_batch"):
        parse_config(TrainConfig, ["--algo", "ppo", "--frames-per-batch", "96"])
    with pytest.raises(ConfigError, match=r"^--total-frames: 128 is less than one batch of 256 frames"):
        learner_settings(
            recipe_config("ppo", learner={"total_frames": 128}), "ppo", domains.part("four_rooms", LearnerDomain)
        )
    with pytest.raises(ConfigError, match=r"^--reward-scale: must be > 0, got -1.0"):
        parse_config(TrainConfig, ["--algo", "a2c", "--reward-scale", "-1"])


def test_the_unshaped_method_is_named_after_the_learner() -> None:
    assert [list(learner_methods(algo))[2] for algo in ("a2c", "ppo", "dqn", "ddpg")] == ["A2C", "PPO", "DQN", "DDPG"]


def test_the_plan_stores_the_learner_and_reports_frames() -> None:
    plan = learner_plan(recipe_config("dqn", "mountain_car", learner={"total_frames": 1600}, results="r"), "dqn")
    assert plan.domain == "dqn_mountain_car" and plan.episodes == 100 and plan.chunk_size == 1
    assert [spec.name for spec in plan.specs] == ["DQN", "HRS-D", "NRS"]  # in --methods order
    config = plan.config
    assert (
        config["algo"] == "dqn"
        and config["learner"]["total_frames"] == 1600
        and config["routes"] == ["swing_then_speed"]
    )
    assert config["report"]["frames_per_unit"] == 16 and config["report"]["asymptotic_window"] == [90, 100]


@pytest.mark.parametrize("monotone", [False, True])
def test_monotone_potential_reaches_the_shaped_learners_table(
    monotone: bool, tmp_path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from torchrl_subgoal.experiments import learners
    from torchrl_subgoal.experiments.store import Chunk

    made = []

    def recording(*args, **kwargs):
        parts = shaping_parts(*args, **kwargs)
        made.append(parts[1] if parts is not None else None)
        return parts

    shaping_parts = learners.shaping_parts
    monkeypatch.setattr(learners, "shaping_parts", recording)
    cfg = recipe_config(
        methods="A2C,HRS", learner={"total_frames": 256}, results=str(tmp_path), monotone_potential=monotone
    )
    plan = learner_plan(cfg, "a2c")
    # recorded either way: results made before the progress prior (no such entry) do not resume under it
    assert plan.config["monotone_potential"] == monotone and plan.config["progress_scale"] == 1.0
    for spec in plan.specs:  # A2C (pattern "none"), HRS (the first participant's)
        chunk = Chunk(spec.name, 0, ((spec.patterns[0], 0),), seed=1)
        learners.run_learner_chunk(chunk, plan.config, lambda done: None)
    assert made[0] is None and made[1].monotone == monotone


def test_the_progress_prior_is_in_the_envs_reward_units(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--progress-scale is the goal's worth in the env's units; the learner's reward_scale applies to it as to the
    reward (DQN on four-rooms with a step cost learns from rewards x 0.01)."""
    from torchrl_subgoal.experiments import learners
    from torchrl_subgoal.experiments.store import Chunk

    class Made(Exception):
        pass

    def recording(*args, **kwargs):
        raise Made(kwargs["progress_scale"])

    monkeypatch.setattr(learners, "shaping_parts", recording)
    cfg = recipe_config("dqn", "four_rooms_step", methods="DQN,HRS", progress_scale=2.0, results=str(tmp_path))
    plan = learner_plan(cfg, "dqn")
    hrs = next(spec for spec in plan.specs if spec.name == "HRS")
    with pytest.raises(Made) as made:
        learners.run_learner_chunk(Chunk("HRS", 0, ((hrs.patterns[0], 0),), seed=1), plan.config, lambda done: None)
    assert made.value.args[0] == pytest.approx(2.0 * 0.01)


def test_the_potential_update_candidates_reach_the_learners_shaping(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--prior-weight and --achievement-reward are stored (only when given, so that earlier results resume) and
    reach each shaped learner's transform; the achievement reward in the env's units, scaled as the reward."""
    from torchrl_subgoal.experiments import learners
    from torchrl_subgoal.experiments.store import Chunk

    class Made(Exception):
        pass

    def recording(make_envs, settings, *, shaping, **kwargs):
        raise Made(shaping)

    assert "prior_weight" not in learner_plan(recipe_config(results=str(tmp_path / "plain")), "a2c").config
    cfg = recipe_config(
        "dqn", "four_rooms_step", methods="DQN,HRS", prior_weight=3.0, achievement_reward=2.0, results=str(tmp_path)
    )
    plan = learner_plan(cfg, "dqn")
    assert plan.config["prior_weight"] == 3.0 and plan.config["achievement_reward"] == 2.0
    monkeypatch.setitem(learners.LEARNERS, "dqn", dataclasses.replace(learners.LEARNERS["dqn"], train=recording))
    hrs = next(spec for spec in plan.specs if spec.name == "HRS")
    with pytest.raises(Made) as made:
        learners.run_learner_chunk(Chunk("HRS", 0, ((hrs.patterns[0], 0),), seed=1), plan.config, lambda done: None)
    (shaping,) = made.value.args[0]
    assert shaping.prior_weight == 3.0 and shaping.loss == {"achievement_reward": pytest.approx(2.0 * 0.01)}
    transform = shaping.transform(shaping.potential, 0.99, 0.05)
    assert transform.value_update.prior_weight == 3.0
    assert transform.value_update.loss.achievement_reward == pytest.approx(0.02)
    with pytest.raises(ConfigError, match="--prior-weight: must be a finite number >= 0"):
        recipe_config(prior_weight=-1.0)


def test_the_learner_sees_z_by_its_own_default_unless_told() -> None:
    """DQN reads z whenever shaped (its default), A2C's and PPO's critics do; --sees-subgoal True, False, None
    or critic overrides."""
    four_rooms = domains.part("four_rooms", LearnerDomain)
    algos = ("dqn", "ppo", "a2c")
    default = {algo: learner_settings(LearnerRecipeConfig(), algo, four_rooms).sees_subgoal for algo in algos}
    assert default == {"dqn": None, "ppo": "critic", "a2c": "critic"}
    assert parse_config(TrainConfig, ["--algo", "dqn", "--sees-subgoal", "False"]).learner.sees_subgoal is False
    assert parse_config(TrainConfig, ["--algo", "ppo", "--sees-subgoal", "True"]).learner.sees_subgoal is True
    assert parse_config(TrainConfig, ["--algo", "ppo", "--sees-subgoal", "None"]).learner.sees_subgoal is None
    assert parse_config(TrainConfig, ["--algo", "a2c", "--sees-subgoal", "critic"]).learner.sees_subgoal == "critic"


def _tables_file(tmp_path, tables) -> str:
    path = tmp_path / "tables.json"
    path.write_text(json.dumps(tables))
    return str(path)


def test_a_frozen_potential_shapes_from_the_first_step_and_never_learns(tmp_path) -> None:
    from torchrl_subgoal.experiments import learners
    from torchrl_subgoal.experiments.store import Chunk

    first = next(iter(load_patterns(domains.part("four_rooms", LearnerDomain).participants, domain="four_rooms")))
    frozen = {first: [0.2, 0.5, 0.9]}
    cfg = recipe_config(
        methods="HRS",
        learner={"total_frames": 512},
        results=str(tmp_path / "run"),
        frozen_potential=_tables_file(tmp_path, frozen),
    )
    with pytest.raises(ConfigError, match=r"no table for pattern 'participant_2' \(HRS\)"):
        learner_plan(cfg, "a2c")  # every participant's pattern needs one
    patterns = load_patterns(domains.part("four_rooms", LearnerDomain).participants, domain="four_rooms")
    tables = {name: [0.2, 0.5, 0.9] for name in patterns}
    cfg.frozen_potential = _tables_file(tmp_path, tables)
    plan = learner_plan(cfg, "a2c")
    assert plan.config["frozen_potential"] == tables  # stored: resuming with other tables is another experiment
    learners.run_learner_chunk(Chunk("HRS", 0, ((first, 0),), seed=1), plan.config, lambda done: None)
    logged = tmp_path / "run" / "logs" / f"HRS_{first}_0" / "scalars"
    for z, value in enumerate([0.2, 0.5, 0.9]):
        rows = (logged / f"potential_z{z}.csv").read_text().split()
        assert [float(r.split(",")[1]) for r in rows] == pytest.approx([value, value])  # after each of 2 batches
    assert "frozen_potential" not in learner_plan(LearnerRecipeConfig(methods="HRS"), "a2c").config


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, r"cannot read it"),
        ("{not json", r"not valid JSON \(line 1"),
        ("[0.1, 0.2]", r"expected an object \{pattern: \[V\(z0\), V\(z1\), \.\.\.\]\}, got list"),
        ('{"participant_1": [0.1, "x", 0.3]}', r"pattern 'participant_1': expected 3 finite numbers"),
        ('{"participant_1": [0.1, 0.3]}', r"pattern 'participant_1': expected 3 finite numbers .* got \[0\.1, 0\.3\]"),
    ],
)
def test_a_bad_frozen_potential_file_names_the_file_and_the_pattern(tmp_path, content, message) -> None:
    path = tmp_path / "tables.json"
    if content is not None:
        path.write_text(content)
    cfg = LearnerRecipeConfig(methods="HRS", frozen_potential=str(path), results=str(tmp_path / "run"))
    with pytest.raises(ConfigError, match=rf"^--frozen-potential: {path}: {message}"):
        learner_plan(cfg, "a2c")
    assert not (tmp_path / "run").exists()  # nothing written before the check


def test_a_frozen_potential_needs_a_method_that_learns_a_table(tmp_path) -> None:
    cfg = LearnerRecipeConfig(methods="A2C,NRS", frozen_potential=_tables_file(tmp_path, {}))
    with pytest.raises(ConfigError, match=r"^--frozen-potential: no method of --methods learns a table"):
        learner_plan(cfg, "a2c")
