"""The ``torchrl-subgoal`` command: its subcommands reach the recipes, the report and the studio, and a
missing extra or an unknown name is one line and exit code 2."""

from __future__ import annotations

import importlib
import subprocess
from pathlib import Path

import pytest

from torchrl_subgoal import console

BIN = Path(__file__).resolve().parents[1] / ".venv" / "bin"


def test_help_lists_every_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    assert console.main(["--help"]) == 0
    out = capsys.readouterr().out
    assert all(f"\n  {name}" in out for name in ("train", "reproduce", "report", "studio"))
    assert console.main(["reproduce", "--help"]) == 0
    assert "{four-rooms,pinball,pick-and-place}" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["nope"], "error: unknown command 'nope'"),
        (["reproduce", "cartpole"], "error: unknown reproduction 'cartpole'; choose from four-rooms, pinball, "),
        (["reproduce"], "error: name a reproduction: choose from four-rooms"),
    ],
)
def test_unknown_names_are_usage_errors(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert console.main(argv) == 2
    assert capsys.readouterr().err.startswith(message)


def test_subcommands_run_the_recipes_under_their_own_name(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        console.main(["train", "--algo", "sac"])
    assert exit_.value.code == 2
    assert "(see torchrl-subgoal train --help)" in capsys.readouterr().err
    assert console.main(["reproduce", "four-rooms", "--episodes", "0"]) == 2
    assert capsys.readouterr().err == "error: --episodes: must be >= 1, got 0\n"
    assert console.main(["report", "/nonexistent/results"]) == 2
    assert "holds no results" in capsys.readouterr().err


def test_a_missing_extra_is_named(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    real = importlib.import_module

    def without_tyro(name: str, package: str | None = None) -> object:
        if name == "torchrl_subgoal.recipes.train":
            raise ModuleNotFoundError("No module named 'tyro'", name="tyro")
        return real(name, package)

    monkeypatch.setattr(console.importlib, "import_module", without_tyro)
    assert console.main(["train"]) == 2
    assert capsys.readouterr().err == (
        "error: torchrl-subgoal train needs the experiments extra (missing: tyro): "
        "pip install 'torchrl_subgoal[experiments]'\n"
    )


def test_the_installed_script_runs() -> None:
    done = subprocess.run([str(BIN / "torchrl-subgoal"), "reproduce", "--help"], capture_output=True, text=True)
    assert done.returncode == 0 and "four-rooms" in done.stdout
