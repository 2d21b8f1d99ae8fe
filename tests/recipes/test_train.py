"""``torchrl-subgoal train`` end to end on tiny budgets (each learner on a domain it fits), resume, ``--config``,
the loggers, and the checks made before the first chunk: one line on stderr naming the flag, nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from torchrl_subgoal.recipes import train


def run(tmp_path: Path, *args: str) -> int:
    return int(train.main([*args, "--workers", "0", "--results", str(tmp_path / "res")]))


def test_dqn_on_mountain_car_reports_frames_and_resumes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--algo", "dqn", "--domain", "mountain_car", "--total-frames", "320"]
    assert run(tmp_path, *args) == 0
    out = capsys.readouterr().out
    assert "One update is 16 frames" in out and "mean frames" in out and "| 120 | HRS-D |" in out
    summary = json.loads((tmp_path / "res" / "summary.json").read_text())
    assert set(summary["methods"]) == {"DQN", "HRS-D", "NRS"}  # the default methods: unshaped, the default, NRS
    assert summary["n_episodes"] == 20 and summary["unit"] == "update" and summary["frames_per_unit"] == 16
    config = json.loads((tmp_path / "res" / "config.json").read_text())["config"]
    assert config["learner"]["lr"] == 0.004 and config["start_potential"] == "nonpositive"  # the preset; the default
    assert (tmp_path / "res" / "patterns.png").stat().st_size > 5_000
    chunks = sorted((tmp_path / "res").glob("chunks/*/*.parquet"))
    mtimes = [c.stat().st_mtime_ns for c in chunks]
    assert run(tmp_path, *args) == 0  # resumes: nothing recomputed
    assert [c.stat().st_mtime_ns for c in chunks] == mtimes


@pytest.mark.parametrize("algo", ["a2c", "ppo"])
def test_on_policy_learners_on_four_rooms(tmp_path: Path, algo: str) -> None:
    args = [
        "--algo",
        algo,
        "--domain",
        "four_rooms",
        "--methods",
        f"{algo.upper()},HRS,SARSA-RS",
        "--learnings",
        "1",
        "--total-frames",
        "512",
        "--sees-subgoal",
        "True",
    ]
    assert run(tmp_path, *args) == 0
    summary = json.loads((tmp_path / "res" / "summary.json").read_text())
    assert summary["methods"]["HRS"]["learners"] == 10 and summary["n_episodes"] == 2  # 10 patterns; 2 x 256


@pytest.mark.parametrize("algo", ["a2c", "ppo", "dqn"])
def test_learners_as_seed_batches_report_and_resume(tmp_path: Path, algo: str) -> None:
    """``--seed-batch 4``: each method's learners train four at a time in one process; every learner reported and
    logged; a re-run resumes; another batch size is another experiment."""
    methods = [algo.upper(), "HRS", "NRS", "SARSA-RS"]
    args = ["--algo", algo, "--methods", ",".join(methods), "--total-frames", "512", "--seed-batch", "4"]
    assert run(tmp_path, *args) == 0
    summary = json.loads((tmp_path / "res" / "summary.json").read_text())
    assert {m: summary["methods"][m]["learners"] for m in summary["methods"]} == dict.fromkeys(methods, 10)
    config = json.loads((tmp_path / "res" / "config.json").read_text())
    assert config["chunk_size"] == 4
    assert len(list((tmp_path / "res" / "logs").glob("HRS_*/scalars/potential_z2.csv"))) == 10
    chunks = sorted((tmp_path / "res").glob("chunks/*/*.parquet"))
    mtimes = [c.stat().st_mtime_ns for c in chunks]
    assert run(tmp_path, *args) == 0  # resumes: nothing recomputed
    assert [c.stat().st_mtime_ns for c in chunks] == mtimes
    assert run(tmp_path, *args[:-1], "2") == 2  # chunks of 2 learners are another experiment's


@pytest.mark.parametrize(("algo", "batch"), [("ppo", "1"), ("ddpg", "1"), ("ddpg", "2")])
def test_continuous_learners_on_point_maze(tmp_path: Path, algo: str, batch: str) -> None:
    """Each pattern of the maze is one direction of its route: HRS runs one learner per pattern, the unshaped
    learner as many, the directions picked by learning number; as a seed batch, each learner of the batch
    runs its own task."""
    args = [
        "--algo",
        algo,
        "--domain",
        "point_maze_umaze",
        "--methods",
        f"{algo.upper()},HRS",
        "--total-frames",
        "256",
        "--frames-per-batch",
        "128",
        "--num-envs",
        "2",
        "--seed-batch",
        batch,
        *(["--reshape-samples"] if algo == "ddpg" else []),
    ]
    assert run(tmp_path, *args) == 0
    summary = json.loads((tmp_path / "res" / "summary.json").read_text())
    assert summary["methods"]["HRS"]["patterns"] == ["bottom_to_top", "top_to_bottom"]
    assert summary["methods"][algo.upper()]["learners"] == 2 and summary["n_episodes"] == 2


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--algo", "ddpg", "--domain", "four_rooms"],
            "--algo: ddpg needs continuous actions; four_rooms's are discrete: choose a2c, ppo or dqn",
        ),
        (
            ["--algo", "dqn", "--domain", "point_maze_umaze"],
            "--algo: dqn needs discrete actions; point_maze_umaze's are continuous: choose ppo or ddpg",
        ),
        (
            ["--algo", "a2c", "--domain", "point_maze_medium"],
            "--algo: a2c needs discrete actions; point_maze_medium's are continuous: choose ppo or ddpg",
        ),
        (["--algo", "ppo", "--reshape-samples"], "--reshape-samples: a setting of dqn and ddpg, not of ppo"),
        (["--algo", "dqn", "--clip-epsilon", "0.1"], "--clip-epsilon: a setting of ppo, not of dqn"),
        (
            ["--domain", "pick_and_place"],
            "--domain: domain 'pick_and_place' registered no LearnerDomain; the domains that did: acrobot, four_rooms,",
        ),
        (["--domain", "chess"], "--domain: unknown domain 'chess'; choose from acrobot, four_rooms, four_rooms_step, "),
        (
            ["--algo", "dqn", "--domain", "mountain_car", "--methods", "DQN,SARSA-RS"],
            "--methods: SARSA-RS needs an aggregation g(s), which mountain_car does not register",
        ),
        (["--algo", "dqn", "--methods", "PPO"], "--methods: unknown method(s) ['PPO']"),
        (["--algo", "ppo", "--num-envs", "3"], "frames_per_batch (256) must be a multiple of num_envs"),
        (["--algo", "ppo", "--total-frames", "100"], "--total-frames: 100 is less than one batch of 256 frames"),
        (["--algo", "dqn", "--value-lr", "0"], "--value-lr: must lie in (0, 1], got 0.0"),
        (["--algo", "ppo", "--clip-epsilon", "nan"], "--clip-epsilon: must be a finite number, got nan"),
        (["--algo", "ppo", "--epochs", "many"], "argument --epochs: invalid int value: 'many'"),
        (["--logger", "mlflow"], "argument --logger: invalid choice: 'mlflow'"),
        (["--algo", "dqn", "--learnings", "0"], "--learnings: must be >= 1, got 0"),
        (["--algo", "sac"], "argument --algo: invalid choice: 'sac'"),
        (
            ["--algo", "ppo", "--domain", "point_maze_umaze", "--seed-batch", "2", "--env-workers", "2"],
            "--seed-batch: point_maze_umaze gives each learner its own task",
        ),
        (["--seed-batch", "0"], "--seed-batch: must be >= 1, got 0"),
        (["--algo", "a2c", "--seed-batch", "2", "--no-online-potential"], "--seed-batch: trains each learner's table"),
        (
            ["--algo", "a2c", "--seed-batch", "2", "--collector-workers", "1"],
            "--seed-batch: needs --collector-workers 0",
        ),
    ],
)
def test_bad_settings_are_one_line_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    try:
        code = run(tmp_path, *args)
    except SystemExit as exit_:  # a flag the parser refuses exits as argparse does
        code = int(exit_.code or 0)
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1 and message in err, err
    assert not (tmp_path / "res").exists()


def test_a_point_maze_file_whose_pattern_names_no_route(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    subgoals = tmp_path / "mine.yaml"
    subgoals.write_text("patterns:\n  alice:\n    subgoals:\n      - {circle: {centre: [1.0, -1.0], radius: 0.6}}\n")
    assert run(tmp_path, "--algo", "ppo", "--domain", "point_maze_umaze", "--subgoals", str(subgoals)) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --subgoals: ") and "pattern 'alice' names no route of the umaze maze" in err


MOUNTAIN_CAR = ["--algo", "dqn", "--domain", "mountain_car", "--total-frames", "320"]


def test_config_json_records_the_run_and_config_reruns_it(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """The command, its settings (a learner's own flag among them) and the code's version are recorded;
    ``--config`` runs the same experiment again elsewhere, and TorchRL's INFO lines stay off the terminal."""
    from torchrl_subgoal.experiments import load_frame

    args = [*MOUNTAIN_CAR, "--methods", "DQN,HRS", "--lr", "0.002", "--workers", "0"]
    assert train.main([*args, "--results", str(tmp_path / "first")], prog="torchrl-subgoal train") == 0
    assert "[torchrl][INFO]" not in capfd.readouterr().err
    manifest = json.loads((tmp_path / "first" / "config.json").read_text())
    provenance = manifest["provenance"]
    assert provenance["command"].startswith("torchrl-subgoal train --algo dqn --domain mountain_car")
    assert provenance["settings"]["learner"]["lr"] == 0.002 and provenance["version"] == "0.1.0"
    assert manifest["config"]["learner"]["lr"] == 0.002 and manifest["runtime"] == {"logger": "csv"}
    again = ["--config", str(tmp_path / "first" / "config.json"), "--results", str(tmp_path / "again")]
    assert train.main(again, prog="torchrl-subgoal train") == 0
    rerun = json.loads((tmp_path / "again" / "config.json").read_text())["config"]
    assert {**rerun, "log_dir": ""} == {**manifest["config"], "log_dir": ""}
    assert load_frame(tmp_path / "again").equals(load_frame(tmp_path / "first"))
    capfd.readouterr()
    assert train.main(["--config", str(tmp_path / "missing.json")]) == 2
    assert capfd.readouterr().err.startswith(f"error: --config: {tmp_path / 'missing.json'}: cannot read it")


@pytest.mark.parametrize("logger", ["tensorboard", "wandb"])
def test_loggers_on_the_command_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, logger: str) -> None:
    """``--logger tensorboard`` writes TensorBoard event files, ``--logger wandb`` W&B runs (offline here), one per
    learner; a resumed sweep may log with another logger (it does not change the results)."""
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.setenv("WANDB_DIR", str(tmp_path / "wandb"))
    assert run(tmp_path, *MOUNTAIN_CAR, "--methods", "DQN,NRS", "--logger", logger) == 0
    logs = tmp_path / "res" / "logs"
    if logger == "tensorboard":
        assert len(list(logs.glob("*/events.out.tfevents.*"))) == 2
    else:
        runs = list(logs.glob("wandb/offline-run-*/run-*.wandb"))
        assert len(runs) == 2 and all(r.stat().st_size > 0 for r in runs)
    assert run(tmp_path, *MOUNTAIN_CAR, "--methods", "DQN,NRS", "--logger", "none") == 0  # resumes
