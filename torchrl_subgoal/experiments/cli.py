"""Typed recipe settings: one dataclass, one ``--flag`` per field, clear errors for bad values."""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Sequence
from typing import Any, Literal, NoReturn, TypeVar, get_args, get_origin, get_type_hints

__all__ = ["ConfigError", "OneLineParser", "parse_config", "setting"]

T = TypeVar("T")


class ConfigError(ValueError):
    """A bad setting; the message names the field (``--flag``) and what is allowed.

    Examples:
        >>> try:
        ...     check(False, "learnings", "must be >= 1, got 0")
        ... except ConfigError as error:
        ...     print(error)
        --learnings: must be >= 1, got 0
    """


class OneLineParser(argparse.ArgumentParser):
    """An :class:`argparse.ArgumentParser` whose usage errors are one line on stderr (exit 2).

    Examples:
        >>> import contextlib, io
        >>> parser = OneLineParser(prog="recipe.py")
        >>> _ = parser.add_argument("--episodes", type=int)
        >>> err = io.StringIO()
        >>> with contextlib.redirect_stderr(err):
        ...     try:
        ...         parser.parse_args(["--episodes", "many"])
        ...     except SystemExit as exit:
        ...         print(exit.code)
        2
        >>> print(err.getvalue().strip())
        error: argument --episodes: invalid int value: 'many' (see recipe.py --help)
    """

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"error: {message} (see {self.prog} --help)\n")


def setting(default: Any, help: str, *, choices: Sequence[Any] | None = None) -> Any:
    """A dataclass field with its help text (and allowed values) for the command line.

    Examples:
        >>> from dataclasses import dataclass
        >>> @dataclass
        ... class Config:
        ...     episodes: int = setting(1000, "episodes per learning")
        ...     def __post_init__(self):
        ...         check(self.episodes >= 1, "episodes", f"must be >= 1, got {self.episodes}")
        >>> parse_config(Config, ["--episodes", "20"])
        Config(episodes=20)
    """
    return dataclasses.field(default=default, metadata={"help": help, "choices": choices})


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def parse_config(cls: type[T], argv: Sequence[str] | None = None, description: str | None = None) -> T:
    """Build ``cls`` (a dataclass of settings) from command-line flags.

    Every field ``foo_bar`` becomes ``--foo-bar`` (booleans: ``--foo-bar`` /
    ``--no-foo-bar``). Values are converted with the field's type; fields with
    ``choices`` only accept those; float values must be finite. The dataclass's ``__post_init__`` may raise
    :class:`ConfigError` for other checks.

    Examples:
        >>> from dataclasses import dataclass
        >>> @dataclass
        ... class Config:
        ...     episodes: int = setting(1000, "episodes per learning")
        ...     def __post_init__(self):
        ...         check(self.episodes >= 1, "episodes", f"must be >= 1, got {self.episodes}")
        >>> parse_config(Config, []).episodes
        1000
        >>> parse_config(Config, ["--episodes", "0"])
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --episodes: must be >= 1, got 0
    """
    hints = get_type_hints(cls)
    parser = OneLineParser(description=description or (cls.__doc__ or "").strip().splitlines()[0])
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        kind = hints[f.name]
        help_text = f"{f.metadata.get('help', '')} (default: {f.default})"
        if kind is bool:
            parser.add_argument(_flag(f.name), action=argparse.BooleanOptionalAction, default=f.default,
                                help=help_text)
        elif get_origin(kind) is Literal:
            options = get_args(kind)
            parser.add_argument(_flag(f.name), type=type(options[0]), default=f.default, help=help_text,
                                choices=options, metavar=f.name.upper())
        else:
            parser.add_argument(_flag(f.name), type=kind, default=f.default, help=help_text,
                                choices=f.metadata.get("choices"), metavar=f.name.upper())
    args = parser.parse_args(argv)
    for name, value in vars(args).items():
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"{_flag(name)}: must be a finite number, got {value}")
    return cls(**vars(args))


def check(condition: bool, field_name: str, message: str) -> None:
    """Raise :class:`ConfigError` for ``--field-name`` unless ``condition`` holds.

    Examples:
        >>> check(3 >= 1, "learnings", "must be >= 1")  # nothing happens
        >>> check(0 >= 1, "learnings", "must be >= 1, got 0")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --learnings: must be >= 1, got 0
    """
    if not condition:
        raise ConfigError(f"{_flag(field_name)}: {message}")
