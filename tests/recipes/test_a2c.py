"""recipes/a2c.py end to end on tiny settings: every method, the report, resume, logs, bad settings."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from .test_recipes import recipe


def test_a2c_recipe_four_rooms_every_method(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a2c = recipe("a2c")
    args = [
        "--domain",
        "four_rooms",
        "--methods",
        "A2C,HRS,RRS,NRS,SARSA-RS",
        "--learnings",
        "1",
        "--total-frames",
        "1024",
        "--random-patterns",
        "2",
        "--workers",
        "0",
        "--results",
        str(tmp_path),
    ]
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
    args = [
        "--domain",
        "pinball",
        "--methods",
        "A2C,HRS",
        "--total-frames",
        "512",
        "--workers",
        "0",
        "--subgoals",
        str(
            Path(__file__).resolve().parents[2]
            / "torchrl_subgoal"
            / "domains"
            / "pinball"
            / "pinball_participants.yaml"
        ),
        "--results",
        str(tmp_path),
    ]
    assert a2c.main(args) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["methods"]["HRS"]["learners"] == 10


@pytest.mark.parametrize(
    ("flag", "value"),
    [
        ("--num-envs", "0"),
        ("--value-lr", "0"),
        ("--methods", "DQN"),
        ("--frames-per-batch", "100"),
        ("--reward-scale", "-1"),
    ],
)
def test_a2c_bad_settings_name_the_flag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flag: str, value: str
) -> None:
    a2c = recipe("a2c")
    assert a2c.main([flag, value, "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and len(err.strip().splitlines()) == 1


def test_a_resumed_learner_logs_one_series(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A learner that was running when the sweep was killed (its logs written, its chunk not) is run again
    from its start on resume: its CSV logs hold the new run only, as its Parquet data does."""
    subgoals = tmp_path / "one.yaml"
    subgoals.write_text("domain: four_rooms\npatterns:\n  p: {subgoals: [{cell: [3, 6]}, {cell: [7, 9]}]}\n")
    results = tmp_path / "res"
    args = [
        "--domain",
        "four_rooms",
        "--methods",
        "A2C,HRS",
        "--subgoals",
        str(subgoals),
        "--learnings",
        "1",
        "--total-frames",
        "1024",
        "--workers",
        "0",
        "--results",
        str(results),
    ]
    a2c = recipe("a2c")
    assert a2c.main(args) == 0
    capsys.readouterr()
    hrs, plain = results / "logs" / "HRS_p_0" / "scalars", results / "logs" / "A2C_none_0" / "scalars"
    steps = [256, 512, 768, 1024]

    def logged(scalars: Path) -> dict[str, list[int]]:
        return {
            f.name: [int(line.split(",")[0]) for line in f.read_text().splitlines()]
            for f in sorted(scalars.glob("*.csv"))
        }

    first = logged(hrs)
    assert set(first) >= {"episode_length.csv", "loss_potential.csv"} and first["episode_length.csv"] == steps
    assert all(frames == sorted(set(frames)) and set(frames) <= set(steps) for frames in first.values()), first
    finished = {f: f.read_bytes() for f in plain.glob("*.csv")}
    # as if killed while the HRS learner ran: half its series logged, the last line torn, no chunk file
    (results / "chunks" / "HRS" / "00000.parquet").unlink()
    for log in hrs.glob("*.csv"):
        log.write_text("".join(log.read_text().splitlines(keepends=True)[:2]) + "7")
    (hrs.parent / "notes.txt").write_text("mine\n")
    assert a2c.main(args) == 0
    capsys.readouterr()
    assert logged(hrs) == first  # one series per scalar, as the first run logged it
    assert {f: f.read_bytes() for f in plain.glob("*.csv")} == finished  # a finished learner's log: untouched
    assert (hrs.parent / "notes.txt").read_text() == "mine\n"
