"""recipes/a2c.py end to end on tiny settings: every method, the report, resume, logs, bad settings."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from .test_recipes import recipe


def test_a2c_recipe_four_rooms_every_method(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a2c = recipe("a2c")
    args = ["--domain", "four_rooms", "--methods", "A2C,HRS,RRS,NRS,SARSA-RS", "--learnings", "1",
            "--total-frames", "1024", "--random-patterns", "2", "--workers", "0", "--results", str(tmp_path)]
    assert a2c.main(args) == 0
    out = capsys.readouterr().out
    assert "| 100 | HRS |" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary["methods"]) == {"A2C", "HRS", "RRS", "NRS", "SARSA-RS"}
    assert summary["methods"]["A2C"]["learners"] == 10 and summary["n_episodes"] == 4  # 4 batches of 256
    assert summary["unit"] == "update"
    logs = list((tmp_path / "logs").rglob("episode_length*.csv"))
    assert len(logs) == 10 + 10 + 2 + 10 + 10
    chunks = sorted(tmp_path.glob("chunks/*/*.parquet"))
    mtimes = [c.stat().st_mtime_ns for c in chunks]
    assert a2c.main(args) == 0  # resumes: nothing recomputed
    assert [c.stat().st_mtime_ns for c in chunks] == mtimes


def test_a2c_recipe_pinball_runs(tmp_path: Path) -> None:
    a2c = recipe("a2c")
    args = ["--domain", "pinball", "--methods", "A2C,HRS", "--total-frames", "512", "--workers", "0",
            "--subgoals", str(Path(__file__).resolve().parents[2] / "torchrl_subgoal" / "data" /
                              "pinball_participants.yaml"), "--results", str(tmp_path)]
    assert a2c.main(args) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["methods"]["HRS"]["learners"] == 10


@pytest.mark.parametrize(("flag", "value"), [("--num-envs", "0"), ("--value-lr", "0"),
                                             ("--methods", "DQN"), ("--frames-per-batch", "100"),
                                             ("--reward-scale", "-1")])
def test_a2c_bad_settings_name_the_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str], flag: str,
                                        value: str) -> None:
    a2c = recipe("a2c")
    assert a2c.main([flag, value, "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and len(err.strip().splitlines()) == 1
