"""recipes/qlearning.py end to end on tiny settings: every method on four-rooms and Taxi, the stored target,
resume, bad settings."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from .test_recipes import recipe


def test_qlearning_recipe_four_rooms_every_method(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    qlearning = recipe("qlearning")
    args = [
        "--domain",
        "four_rooms",
        "--reward",
        "goal",
        "--learnings",
        "1",
        "--episodes",
        "3",
        "--workers",
        "0",
        "--results",
        str(tmp_path),
    ]
    assert qlearning.main(args) == 0
    assert "| 50 | HRS-mean |" in capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary["methods"]) == {"Q", "HRS-D", "HRS", "HRS-mean", "NRS"}  # the default methods
    assert summary["methods"]["HRS"]["learners"] == 10 and summary["n_episodes"] == 3
    config = json.loads((tmp_path / "config.json").read_text())
    stored = config.get("config", config)
    assert stored["target"] == {"expectile": 0.9, "bootstrap_truncated": False}
    chunks = sorted(tmp_path.glob("chunks/*/*.parquet"))
    mtimes = [c.stat().st_mtime_ns for c in chunks]
    assert qlearning.main(args) == 0  # resumes: nothing recomputed
    assert [c.stat().st_mtime_ns for c in chunks] == mtimes


def test_qlearning_recipe_taxi_runs(tmp_path: Path) -> None:
    qlearning = recipe("qlearning")
    args = [
        "--domain",
        "taxi",
        "--methods",
        "Q,HRS",
        "--learnings",
        "2",
        "--episodes",
        "2",
        "--workers",
        "0",
        "--results",
        str(tmp_path),
    ]
    assert qlearning.main(args) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["methods"]["HRS"]["learners"] == 2


def test_qlearning_recipe_stores_the_potential_update_candidates(tmp_path: Path) -> None:
    """``--prior-weight`` and ``--achievement-reward`` go into the stored target (left out at 0, so that
    results of earlier versions resume)."""
    qlearning = recipe("qlearning")
    args = ["--domain", "taxi", "--methods", "HRS-D", "--learnings", "1", "--episodes", "2", "--workers", "0"]
    candidates = ["--prior-weight", "2", "--achievement-reward", "0.5"]
    assert qlearning.main([*args, *candidates, "--results", str(tmp_path)]) == 0
    stored = json.loads((tmp_path / "config.json").read_text())["config"]["target"]
    assert stored == {"expectile": 0.9, "bootstrap_truncated": False, "prior_weight": 2.0, "achievement_reward": 0.5}


@pytest.mark.parametrize(
    ("flag", "value"),
    [
        ("--expectile", "1.0"),
        ("--lr", "0"),
        ("--methods", "SARSA"),
        ("--epsilon", "1.5"),
        ("--prior-weight", "-1"),
        ("--achievement-reward", "nan"),
    ],
)
def test_qlearning_bad_settings_name_the_flag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flag: str, value: str
) -> None:
    qlearning = recipe("qlearning")
    assert qlearning.main([flag, value, "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and len(err.strip().splitlines()) == 1


def test_qlearning_unknown_task_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        recipe("qlearning").main(["--domain", "cartpole"])
    assert exit_info.value.code == 2 and "invalid choice: 'cartpole'" in capsys.readouterr().err
