"""Typed recipe settings: one dataclass, one ``--flag`` per field (parsed by ``tyro``), clear errors for bad values.

``tyro`` builds the command line from the dataclass's fields; what this module
adds is small: each field's help text and allowed values (:func:`setting`),
argparse's spelling of a bad value (``invalid int value: 'many'``), and errors
as one line on stderr with exit code 2 instead of ``tyro``'s boxed message.
The last goes through ``tyro._errors.on_parse_error``, a hook ``tyro`` marks
private and unstable, which is why ``pyproject.toml`` bounds ``tyro`` to the
1.0 series (``tests/experiments/test_cli.py`` checks every message).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
from collections.abc import Callable, Sequence
from typing import Annotated, Any, Literal, NoReturn, TypeVar, get_type_hints

import tyro
from tyro import _errors as tyro_errors

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


class _UsageError(Exception):
    """A command line ``tyro`` rejected, in argparse's words (raised by :func:`_one_line`)."""


def _argument(event: Any) -> str:
    return "argument " + "/".join(event.argument.lowered.name_or_flags)


def _one_line(event: tyro_errors.ParseErrorEvent) -> None:
    """``tyro``'s parse-error hook: every rejection as the line argparse would print."""
    if isinstance(event, tyro_errors.InvalidChoice):
        allowed = ", ".join(repr(c) for c in event.choices)
        raise _UsageError(f"{_argument(event)}: invalid choice: {event.value!r} (choose from {allowed})")
    if isinstance(event, tyro_errors.InstantiationFailure) and event.argument is not None:
        raise _UsageError(f"{_argument(event)}: {event.message}")
    if isinstance(event, tyro_errors.BadValue):
        problem = (
            "expected one argument"
            if event.reason == "too_few_values"
            else f"ignored explicit argument {event.offending_value!r}"
        )
        raise _UsageError(f"{_argument(event)}: {problem}")
    if isinstance(event, tyro_errors.UnrecognizedArgs):
        raise _UsageError(f"unrecognized arguments: {' '.join(event.tokens)}")
    raise _UsageError(getattr(event, "message", type(event).__name__))


def _parsed_as(kind: type) -> Callable[[list[str]], Any]:
    def parse(args: list[str]) -> Any:
        try:
            return kind(args[0])
        except ValueError:
            raise ValueError(f"invalid {kind.__name__} value: {args[0]!r}") from None

    return parse


def _number(kind: type, metavar: str) -> Any:
    """A ``tyro`` spec for an int or float flag whose bad value reads as argparse's ``invalid int value: 'x'``."""
    return tyro.constructors.PrimitiveConstructorSpec(
        nargs=1,
        metavar=metavar,
        instance_from_str=_parsed_as(kind),
        is_instance=lambda value: isinstance(value, kind) and not isinstance(value, bool),
        str_from_instance=lambda value: [str(value)],
    )


def _tyro_field(f: dataclasses.Field, kind: Any) -> tuple[str, Any, Any]:
    """``f`` as a field of the dataclass ``tyro`` parses: its type annotated with the help text and metavar."""
    metavar = f.name.upper()
    choices = f.metadata.get("choices")
    marks: list[Any] = [tyro.conf.arg(help=f.metadata.get("help", ""), metavar=None if kind is bool else metavar)]
    if choices is not None:
        kind = Literal.__getitem__(tuple(choices))
    elif kind in (int, float):
        marks.insert(0, _number(kind, metavar))
    return f.name, Annotated[(kind, *marks)], dataclasses.field(default=f.default)


def parse_config(cls: type[T], argv: Sequence[str] | None = None, description: str | None = None) -> T:
    """Build ``cls`` (a dataclass of settings) from command-line flags, parsed by ``tyro``.

    Every field ``foo_bar`` becomes ``--foo-bar`` (booleans: ``--foo-bar`` /
    ``--no-foo-bar``). Values are converted with the field's type; fields with
    ``choices`` (or a ``Literal`` type) only accept those; float values must be finite.
    The dataclass's ``__post_init__`` may raise :class:`ConfigError` for other checks.
    A command line that does not parse exits with code 2 after one line on stderr,
    ``error: argument --flag: what is wrong (see PROG --help)``.

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
    fields = [f for f in dataclasses.fields(cls) if f.init]  # type: ignore[arg-type]
    flags = dataclasses.make_dataclass(cls.__name__, [_tyro_field(f, hints[f.name]) for f in fields])
    prog = os.path.basename(sys.argv[0])
    try:
        with tyro_errors.on_parse_error(_one_line):
            parsed: Any = tyro.cli(
                flags,
                args=list(argv) if argv is not None else None,
                prog=prog,
                description=description or (cls.__doc__ or "").strip().splitlines()[0],
            )
    except _UsageError as exc:
        print(f"error: {exc} (see {prog} --help)", file=sys.stderr)
        raise SystemExit(2) from None
    values = {f.name: getattr(parsed, f.name) for f in fields}
    for name, value in values.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"{_flag(name)}: must be a finite number, got {value}")
    return cls(**values)


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
