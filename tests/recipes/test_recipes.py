"""The recipes end to end on tiny settings: results, report, resume, bad settings."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[2]


#: the recipes the package ships (``torchrl-subgoal``); their scripts in recipes/ run the same ``main``
PACKAGED = ("four_rooms", "pinball", "pick_and_place", "train")


def recipe(name: str) -> ModuleType:
    """The recipe ``name``: its module in the package, or the repository's script."""
    if name in PACKAGED:
        return importlib.import_module(f"torchrl_subgoal.recipes.{name}")
    return script(name)


def script(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"recipe_{name}", ROOT / "recipes" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_four_rooms_recipe(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    four_rooms = recipe("four_rooms")
    args = ["--episodes", "30", "--learnings", "2", "--workers", "0", "--results", str(tmp_path)]
    assert four_rooms.main(args) == 0
    out = capsys.readouterr().out
    assert "| 50 | HRS |" in out and "paper mean (s.d.)" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary["methods"]) == {"HRS", "RRS", "SARSA", "NRS", "SARSA-RS"}
    assert summary["methods"]["SARSA"]["learners"] == 20  # 10 patterns x 2 learnings, as the shaped methods
    assert (tmp_path / "learning_curves.png").stat().st_size > 10_000
    assert (tmp_path / "patterns.png").stat().st_size > 10_000
    chunks = sorted(tmp_path.glob("chunks/*/*.parquet"))
    mtimes = [c.stat().st_mtime_ns for c in chunks]
    assert four_rooms.main(args) == 0  # resumes: nothing recomputed
    assert [c.stat().st_mtime_ns for c in chunks] == mtimes


@pytest.mark.slow
def test_four_rooms_engines_agree(tmp_path: Path) -> None:
    four_rooms = recipe("four_rooms")
    frames = []
    for engine in ("torchrl", "fused"):
        out = tmp_path / engine
        args = [
            "--episodes",
            "8",
            "--learnings",
            "1",
            "--workers",
            "0",
            "--methods",
            "HRS,NRS",
            "--engine",
            engine,
            "--results",
            str(out),
        ]
        assert four_rooms.main(args) == 0
        from torchrl_subgoal.experiments import load_frame

        frames.append(load_frame(out))
    assert frames[0].equals(frames[1])


@pytest.mark.slow
@pytest.mark.parametrize("domain", ["four_rooms", "pinball"])
def test_results_do_not_depend_on_chunking_or_workers(tmp_path: Path, domain: str) -> None:
    """Every learner draws from its own streams (seeded by sweep seed, method, pattern, learning):
    the same records with one chunk per method, with chunks of 3 on two workers, and of 7 inline."""
    from torchrl_subgoal.experiments import load_frame

    tiny = (
        ["--episodes", "6", "--learnings", "1", "--methods", "HRS,NRS,SARSA-RS"]
        if domain == "four_rooms"
        else [
            "--episodes",
            "10",
            "--learnings",
            "1",
            "--max-steps",
            "60",
            "--methods",
            "HRS,AC",
            "--step-penalty",
            "-1",
            "--thrust-penalty",
            "-5",
        ]
    )  # returns tell the learners apart
    frames = []
    for chunk_size, workers in (("1000", "0"), ("3", "2"), ("7", "0")):
        out = tmp_path / f"{chunk_size}-{workers}"
        cmd = [
            sys.executable,
            str(ROOT / "recipes" / f"{domain}.py"),
            *tiny,
            "--chunk-size",
            chunk_size,
            "--workers",
            workers,
            "--results",
            str(out),
        ]
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, done.stderr[-2000:]
        frames.append(load_frame(out).sort_values(["method", "pattern", "learning", "episode"], ignore_index=True))
    assert frames[0].equals(frames[1]) and frames[0].equals(frames[2])
    assert len(frames[0][["steps", "return"]].drop_duplicates()) > 3  # the learners did differ


@pytest.mark.parametrize(
    ("flag", "value", "message"),
    [
        ("--episodes", "0", "--episodes: must be >= 1"),
        ("--methods", "HRS,XYZ", "--methods: unknown method(s) ['XYZ']"),
        ("--eta", "-1", "--eta: must be >= 0"),
    ],
)
def test_bad_settings_name_the_flag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flag: str, value: str, message: str
) -> None:
    assert recipe("four_rooms").main([flag, value, "--results", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err


def test_bad_subgoal_file_names_file_and_field(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("patterns:\n  p: {subgoals: [{cell: [0, 0]}]}\n")
    assert recipe("four_rooms").main(["--subgoals", str(bad), "--results", str(tmp_path / "r")]) == 2
    assert f"{bad}: pattern 'p': subgoals[0].cell: (0, 0) is a wall" in capsys.readouterr().err


def test_pinball_recipe(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pinball = recipe("pinball")
    args = ["--episodes", "12", "--learnings", "1", "--max-steps", "300", "--workers", "0", "--results", str(tmp_path)]
    assert pinball.main(args) == 0
    out = capsys.readouterr().out
    assert "| 3000 | HRS |" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["window"] == 10 and set(summary["methods"]) == {"HRS", "RRS", "AC", "NRS", "SARSA-RS"}


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one Ray instance at a time under pytest-xdist
def test_four_rooms_on_ray_equals_local(tmp_path: Path) -> None:
    """The command line with --backend ray (a local Ray instance) gives the local backend's results."""
    from torchrl_subgoal.experiments import load_frame

    frames = []
    for backend in ("local", "ray"):
        out = tmp_path / backend
        cmd = [
            sys.executable,
            str(ROOT / "recipes" / "four_rooms.py"),
            "--episodes",
            "15",
            "--learnings",
            "1",
            "--methods",
            "HRS,SARSA",
            "--chunk-size",
            "5",
            "--backend",
            backend,
            "--workers",
            "2",
            "--results",
            str(out),
        ]
        env = {**os.environ, "RAY_ADDRESS": "local"}  # not a cluster someone else runs on this machine
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
        assert done.returncode == 0, done.stderr[-2000:]
        frames.append(load_frame(out))
    assert len(frames[0]) == 20 * 15 and frames[0].equals(frames[1])


def test_reproductions_default_to_the_authors_conventions() -> None:
    """The recipes follow the authors' released code: the goal step is shaped with γV(z_T), Φ = V; PinBall's
    default agent is their Q-based actor-critic (docs/shaping_defaults.md, docs/pinball.md)."""
    from torchrl_subgoal.fused import AC_PRESETS

    for name in ("four_rooms", "pinball"):
        cfg = recipe(name).Config()
        assert cfg.zero_terminal_potential is False and cfg.start_potential == "value"
    assert AC_PRESETS[recipe("pinball").Config().preset].critic == "action"
    assert AC_PRESETS["paper"].critic == "state"


def test_four_rooms_step_cost_and_library_conventions(tmp_path: Path) -> None:
    from torchrl_subgoal.experiments import load_frame

    args = [
        "--episodes",
        "6",
        "--learnings",
        "1",
        "--methods",
        "HRS,SARSA",
        "--reward",
        "step-cost",
        "--zero-terminal-potential",
        "--start-potential",
        "nonpositive",
        "--workers",
        "0",
        "--results",
        str(tmp_path),
    ]
    assert recipe("four_rooms").main(args) == 0
    frame = load_frame(tmp_path)
    assert (frame["return"] == -(frame["steps"] - frame["success"].astype(int))).all()  # −1 per step, 0 at the goal
    config = json.loads((tmp_path / "config.json").read_text())["config"]
    assert (config["reward"], config["zero_terminal_potential"], config["start_potential"]) == (
        "step-cost",
        True,
        "nonpositive",
    )


def test_pinball_shorter_than_the_report_window(tmp_path: Path) -> None:
    # fewer episodes than the 10-episode moving average: the report smooths over what there is
    pinball = recipe("pinball")
    args = ["--methods", "AC", "--learnings", "1", "--episodes", "2", "--max-steps", "50", "--workers", "0"]
    assert pinball.main([*args, "--results", str(tmp_path)]) == 0
    assert json.loads((tmp_path / "config.json").read_text())["config"]["report"]["window"] == 2
    assert (tmp_path / "report.md").exists()


def test_four_rooms_greedy_recipe(capsys: pytest.CaptureFixture[str]) -> None:
    """Not a sweep: its own table, through the recipes' shared ``config_main`` (one-line errors)."""
    greedy = recipe("four_rooms_greedy")
    assert greedy.main(["--learnings", "1", "--episodes", "3"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    assert len(rows) == 1 + len(greedy.CONVENTIONS) and "10 HRS learners" in rows[0]
    assert greedy.main(["--episodes", "0"]) == 2
    assert capsys.readouterr().err == "error: --episodes: must be >= 1, got 0\n"


@pytest.mark.parametrize("name", PACKAGED)
def test_the_scripts_run_the_packaged_recipes(name: str) -> None:
    assert script(name).main is recipe(name).main
