"""Typed recipe settings: flags from dataclass fields, conversions and clear errors."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import pytest

from torchrl_subgoal.experiments.cli import ConfigError, check, parse_config, setting


@dataclass
class Settings:
    """Toy settings."""

    episodes: int = setting(10, "episodes")
    rate: float = setting(0.5, "a rate")
    name: str = setting("a", "a name", choices=["a", "b"])
    backend: Literal["local", "ray"] = setting("local", "where")
    overwrite: bool = setting(False, "a switch")

    def __post_init__(self) -> None:
        check(self.episodes >= 1, "episodes", f"must be >= 1, got {self.episodes}")


def test_defaults_and_conversions() -> None:
    assert parse_config(Settings, []) == Settings()
    cfg = parse_config(
        Settings, ["--episodes", "3", "--rate", "1e-2", "--name", "b", "--backend", "ray", "--overwrite"]
    )
    assert cfg == Settings(episodes=3, rate=0.01, name="b", backend="ray", overwrite=True)
    assert parse_config(Settings, ["--no-overwrite"]).overwrite is False


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--name", "c"], "--name: invalid choice: 'c'"),
        (["--backend", "slurm"], "--backend: invalid choice: 'slurm'"),
        (["--episodes", "many"], "--episodes: invalid int value: 'many'"),
        (["--rate", "fast"], "--rate: invalid float value: 'fast'"),
        (["--episodes"], "--episodes: expected one argument"),
        (["--bogus", "1"], "unrecognized arguments: --bogus 1"),
    ],
)
def test_bad_values_name_the_flag(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        parse_config(Settings, argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and message in err and err.startswith("error: ") and err.count("\n") == 1


def test_post_init_checks_name_the_flag() -> None:
    with pytest.raises(ConfigError, match="--episodes: must be >= 1, got 0"):
        parse_config(Settings, ["--episodes", "0"])
