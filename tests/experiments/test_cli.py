"""Typed recipe settings: flags from dataclass fields, conversions and clear errors."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar, Literal

import pytest

from torchrl_subgoal.experiments.cli import ConfigError, check, parse_config, setting, settings_data


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


@dataclass
class Inner:
    """A nested group's settings, documented per field."""

    rate: float = 0.1
    """how fast"""
    sizes: tuple[int, ...] = (4, 4)
    """layer sizes"""

    def __post_init__(self) -> None:
        if self.rate <= 0:
            raise ValueError(f"rate must be > 0, got {self.rate}")


@dataclass
class Outer:
    """Settings with a nested group whose defaults depend on an early flag."""

    kind: str = setting("slow", "which defaults", choices=["slow", "fast"])
    num_envs: int = setting(2, "envs")
    inner: Inner | None = field(default=None, metadata={"nested": True})

    EARLY: ClassVar[tuple[str, ...]] = ("kind",)

    @classmethod
    def nested_settings(cls, early: dict) -> dict:
        return {"inner": ("inner", Inner(rate=0.1 if early["kind"] == "slow" else 0.9))}


def test_nested_settings_are_flags_whose_defaults_follow_the_early_ones(capsys: pytest.CaptureFixture[str]) -> None:
    assert parse_config(Outer, []).inner == Inner(0.1)
    assert parse_config(Outer, ["--kind", "fast"]).inner == Inner(0.9)
    assert parse_config(Outer, ["--kind=fast", "--sizes", "8", "--rate", "0.5"]).inner == Inner(0.5, (8,))
    with pytest.raises(ConfigError, match=r"^--rate: must be > 0, got -1.0$"):
        parse_config(Outer, ["--rate", "-1"])
    with pytest.raises(SystemExit):
        parse_config(Outer, ["--kind", "fast", "--help"])
    assert "how fast (default: 0.9)" in " ".join(capsys.readouterr().out.split())


def test_renamed_flags_still_work_and_say_so(capsys: pytest.CaptureFixture[str]) -> None:
    assert parse_config(Outer, ["--envs", "3"]).num_envs == 3
    assert capsys.readouterr().err == "warning: --envs is renamed --num-envs; the old name will go\n"


def test_config_file_gives_the_defaults_the_flags_override(tmp_path: Path) -> None:
    recorded = {"provenance": {"command": "x", "settings": settings_data(Outer("fast", 5, Inner(0.3, (2,))))}}
    (tmp_path / "config.json").write_text(json.dumps(recorded))
    assert parse_config(Outer, ["--config", str(tmp_path)]) == Outer("fast", 5, Inner(0.3, (2,)))
    assert parse_config(Outer, ["--config", str(tmp_path / "config.json"), "--num-envs", "7"]).num_envs == 7
    (tmp_path / "other.json").write_text(json.dumps({"provenance": {"command": "y", "settings": {"episodes": 3}}}))
    with pytest.raises(
        ConfigError, match=r"settings \['episodes'\] are not this command's \(the file was written by y\)"
    ):
        parse_config(Outer, ["--config", str(tmp_path / "other.json")])
    (tmp_path / "bare.json").write_text("{}")
    with pytest.raises(ConfigError, match="records no settings"):
        parse_config(Outer, ["--config", str(tmp_path / "bare.json")])
