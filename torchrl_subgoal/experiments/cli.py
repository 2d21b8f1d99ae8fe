"""Typed recipe settings: one dataclass, one ``--flag`` per field (parsed by ``tyro``), clear errors for bad values.

``tyro`` builds the command line from the dataclass's fields, and a field whose
value is itself a dataclass (a learner's settings, :class:`~torchrl_subgoal.training.PPOConfig`
...) becomes a group of flags, one per field of it, with its docstrings as help.
What this module adds, through ``tyro``'s public API only: each field's help text and
allowed values (:func:`setting`), argparse's spelling of a bad number (``invalid int
value: 'many'``), ``--config FILE`` (the settings a run recorded in its
``config.json``, overridden by the flags given with it), renamed flags that still work
for a while (:data:`RENAMED`), and every rejection as one line on stderr with exit code 2
instead of ``tyro``'s boxed message (``tests/experiments/test_cli.py`` checks every message).
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import dataclasses
import functools
import inspect
import io
import itertools
import json
import math
import os
import re
import sys
import textwrap
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, Literal, NoReturn, TypeVar, get_type_hints

import tyro

__all__ = [
    "RENAMED",
    "ConfigError",
    "OneLineParser",
    "check",
    "flag_of",
    "load_settings",
    "parse_config",
    "setting",
    "settings_data",
]

T = TypeVar("T")

#: What ``--help`` says of ``--config`` (which every command built by :func:`parse_config` takes).
CONFIG_HELP = (
    "\n--config FILE starts from the settings a run recorded (its config.json, or its results directory); "
    "flags given with it override them."
)

#: Flags that were renamed: the old name still works and says so on stderr.
RENAMED = {"--envs": "--num-envs", "--env-processes": "--env-workers", "--task": "--domain"}


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
    """An ``argparse.ArgumentParser`` whose usage errors are one line on stderr (exit 2).

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


def setting(default: Any, help: str, *, choices: Sequence[Any] | None = None, shown_default: str | None = None) -> Any:
    """A dataclass field with its help text (and allowed values) for the command line.

    Args:
        default: the field's default.
        help: what the flag sets.
        choices: the values it takes (the help lists them).
        shown_default: what ``--help`` says the default is, when the default value itself says little
            (``""`` meaning "the learner's unshaped method, HRS and NRS").

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
    metadata = {"help": help, "choices": choices, "shown_default": shown_default}
    return dataclasses.field(default=default, metadata=metadata)


def flag_of(name: str) -> str:
    """The flag of the field ``name``.

    Examples:
        >>> flag_of("frames_per_batch")
        '--frames-per-batch'
    """
    return "--" + name.replace("_", "-")


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


def _annotated(kind: Any, help: str, name: str, choices: Sequence[Any] | None, shown_default: str | None) -> Any:
    """``kind`` annotated for ``tyro``: the help text, the metavar (none where the choices are listed)."""
    marks: list[Any] = []
    hint = f"(default: {shown_default})" if shown_default is not None else None
    if choices is not None:
        kind = Literal.__getitem__(tuple(choices))
        marks.append(tyro.conf.arg(help=help, help_behavior_hint=hint))
    elif kind in (int, float):
        metavar = kind.__name__.upper()
        marks += [_number(kind, metavar), tyro.conf.arg(help=help, metavar=metavar, help_behavior_hint=hint)]
    else:
        marks.append(tyro.conf.arg(help=help, help_behavior_hint=hint))
    return Annotated[(kind, *marks)]


def field_docs(cls: type) -> dict[str, str]:
    """The attribute docstrings of a dataclass's fields (its bases' too), as one line each, for ``--help``.

    Examples:
        >>> from torchrl_subgoal.training import PPOConfig
        >>> field_docs(PPOConfig)["clip_epsilon"]
        "PPO's clip of the probability ratio"
    """
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__[:-1]):
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError, SyntaxError):
            continue
        body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
        for first, second in itertools.pairwise(body):
            if (
                isinstance(first, ast.AnnAssign)
                and isinstance(first.target, ast.Name)
                and isinstance(second, ast.Expr)
                and isinstance(second.value, ast.Constant)
                and isinstance(second.value.value, str)
            ):
                docs[first.target.id] = " ".join(second.value.value.replace("``", "").split())
    return docs


def _nested_flags(default: Any, group: str) -> tuple[type, Any]:
    """A dataclass of flags for the fields of the dataclass instance ``default`` (a learner's settings), and
    its default instance: each field's docstring as help, ``int`` and ``float`` parsed as argparse does."""
    cls = type(default)
    hints, docs = get_type_hints(cls), field_docs(cls)
    fields = [
        (
            f.name,
            _annotated(hints[f.name], docs.get(f.name, ""), f.name, None, None),
            dataclasses.field(default=getattr(default, f.name)),
        )
        for f in dataclasses.fields(cls)
        if f.init
    ]
    flags = dataclasses.make_dataclass(f"{cls.__name__}Flags", fields)
    flags.__doc__ = f"{cls.__name__}: the learner's settings (the defaults shown are the domain's)"
    return flags, flags(**{name: field.default for name, _, field in fields})


def _one_line(message: str, prog: str) -> str:
    """``tyro``'s error message (a box, or its plain-text form when the output is not a terminal) as
    argparse's one line: the box's first paragraph, in argparse's words where it has them.

    Examples:
        >>> box = (
        ...     "╭─ Invalid choice ─────────────────────────────────╮\\n"
        ...     "│ invalid choice 'c' for argument '--name'. Expected one of ('a', 'b'). │\\n"
        ...     "│ ──────────────────────────────────────────────── │\\n"
        ...     "│ For full helptext, run p --help                  │\\n"
        ...     "╰──────────────────────────────────────────────────╯\\n"
        ... )
        >>> _one_line(box, "p")
        "error: argument --name: invalid choice: 'c' (choose from 'a', 'b') (see p --help)"
    """
    lines = re.sub(r"\x1b\[[0-9;]*m", "", message).splitlines()
    ends = [i for i, line in enumerate(lines) if "For full helptext" in line]
    end = ends[-1] if ends else len(lines)
    tops = [i for i in range(end) if lines[i].lstrip().startswith("╭")]
    if tops:
        start = tops[-1] + 1
    else:  # plain text: a title line, a rule, the message (after any help printed before it)
        blanks = [i for i in range(end) if not lines[i].strip()]
        start = (blanks[-1] + 2) if blanks else 1
    body: list[str] = []
    for line in lines[start:end]:
        inner = line.strip().strip("│|").strip()
        if inner and set(inner) <= set("─━-"):
            if body:
                break
            continue
        if inner:
            body.append(inner)
    said = " ".join(" ".join(body).split()) or "the command line does not parse"
    for pattern, replacement in (
        (
            r"^invalid choice '(.*)' for argument '([^']+)'\. Expected one of \((.*)\)\.?$",
            r"argument \2: invalid choice: '\1' (choose from \3)",
        ),
        (r"^Error parsing (--\S+?): (.*)$", r"argument \1: \2"),
        (r"^Missing value for argument '([^']+)'.*$", r"argument \1: expected one argument"),
        (r"^Unrecognized options?: (.*)$", r"unrecognized arguments: \1"),
    ):
        if re.match(pattern, said):
            said = re.sub(pattern, replacement, said)
            break
    if said.startswith("unrecognized arguments: "):
        said = said.replace(", ", " ")
    return f"error: {said} (see {prog} --help)"


def _renamed(argv: Sequence[str]) -> list[str]:
    """``argv`` with the old names of renamed flags (:data:`RENAMED`) replaced, each said once on stderr."""
    out = []
    for arg in argv:
        name, eq, value = arg.partition("=")
        if name in RENAMED:
            print(f"warning: {name} is renamed {RENAMED[name]}; the old name will go", file=sys.stderr)
            arg = RENAMED[name] + eq + value
        out.append(arg)
    return out


def _take(argv: list[str], flag: str) -> tuple[list[str], str | None]:
    """``argv`` without ``flag VALUE`` / ``flag=VALUE``, and the last value given (``None``: not given)."""
    rest, value, i = [], None, 0
    while i < len(argv):
        if argv[i] == flag and i + 1 < len(argv):
            value, i = argv[i + 1], i + 2
            continue
        if argv[i].startswith(flag + "="):
            value = argv[i].split("=", 1)[1]
        else:
            rest.append(argv[i])
        i += 1
    return rest, value


def _given(argv: Sequence[str], flag: str) -> str | None:
    """The last value of ``flag`` in ``argv`` (``None``: not given)."""
    return _take(list(argv), flag)[1]


def settings_data(cfg: Any) -> dict[str, Any]:
    """A settings dataclass as JSON-ready data (what ``config.json`` records and ``--config`` reads back).

    Examples:
        >>> from dataclasses import dataclass
        >>> @dataclass
        ... class Config:
        ...     episodes: int = setting(1000, "episodes per learning")
        ...     hidden: tuple[int, ...] = setting((64, 64), "hidden sizes")
        >>> settings_data(Config())
        {'episodes': 1000, 'hidden': [64, 64]}
    """
    return json.loads(json.dumps(dataclasses.asdict(cfg)))


def load_settings(path: str | os.PathLike[str], cls: type) -> dict[str, Any]:
    """The settings a run recorded (``config.json``'s ``provenance.settings``; a results directory names its
    ``config.json``), checked against the fields of ``cls``.

    Raises:
        ConfigError: naming ``--config``, the file and what is wrong with it.

    Examples:
        >>> import tempfile
        >>> from dataclasses import dataclass
        >>> @dataclass
        ... class Config:
        ...     episodes: int = setting(1000, "episodes per learning")
        >>> folder = Path(tempfile.mkdtemp())
        >>> _ = (folder / "config.json").write_text('{"provenance": {"settings": {"episodes": 20}}}')
        >>> load_settings(folder, Config)
        {'episodes': 20}
    """
    file = Path(path)
    file = file / "config.json" if file.is_dir() else file
    where = f"--config: {file}"
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{where}: cannot read it ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{where}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    settings = data.get("provenance", {}).get("settings") if isinstance(data, dict) else None
    if not isinstance(settings, dict):
        raise ConfigError(f"{where}: records no settings (a config.json a recipe wrote has provenance.settings)")
    known = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(settings) - known)
    if unknown:
        recipe = data.get("provenance", {}).get("command", "another command")
        raise ConfigError(f"{where}: settings {unknown} are not this command's (the file was written by {recipe})")
    return settings


def _early(cls: type, argv: Sequence[str], stored: Mapping[str, Any]) -> dict[str, Any]:
    """The values of ``cls.EARLY`` fields (those its nested settings depend on): given, stored or default."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    out = {}
    for name in getattr(cls, "EARLY", ()):
        given = _given(argv, flag_of(name))
        out[name] = given if given is not None else stored.get(name, fields[name].default)
    return out


def _run_tyro(flags: type, default: Any, argv: Sequence[str], prog: str, description: str) -> Any:
    """``tyro.cli`` on ``flags``; a rejection exits with code 2 after one line on stderr."""
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            return tyro.cli(flags, args=list(argv), prog=prog, description=description, default=default)
    except SystemExit as exc:
        if exc.code in (0, None):
            raise
        print(_one_line(captured.getvalue(), prog), file=sys.stderr)
        raise SystemExit(2) from None


def parse_config(
    cls: type[T], argv: Sequence[str] | None = None, description: str | None = None, *, prog: str | None = None
) -> T:
    """Build ``cls`` (a dataclass of settings) from command-line flags, parsed by ``tyro``.

    Every field ``foo_bar`` becomes ``--foo-bar`` (booleans: ``--foo-bar`` /
    ``--no-foo-bar``). Values are converted with the field's type; fields with
    ``choices`` (or a ``Literal`` type) only accept those; float values must be finite.
    ``--config FILE`` starts from the settings a run recorded in ``FILE`` (its
    ``config.json``, or its results directory) instead of the defaults. A class may
    name fields in ``EARLY`` and give groups of nested settings that depend on them
    (``nested_settings(early) -> {field: (group name, default dataclass instance)}``): the learner
    recipes' ``--algo`` and ``--domain`` pick the learner whose settings are flags; its
    ``check_flags(early, flags)`` may refuse a flag first (another learner's setting).
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
    prog = prog or os.path.basename(sys.argv[0])
    args, config_file = _take(_renamed(sys.argv[1:] if argv is None else argv), "--config")
    stored = load_settings(config_file, cls) if config_file else {}
    hints = get_type_hints(cls)
    early = getattr(cls, "EARLY", ())
    fields = sorted((f for f in dataclasses.fields(cls) if f.init), key=lambda f: f.name not in early)  # type: ignore[arg-type]
    nested: dict[str, Any] = {}
    make_nested = getattr(cls, "nested_settings", None)
    if make_nested is not None:
        early_values = _early(cls, args, stored)
        nested = make_nested(early_values)
        check_flags = getattr(cls, "check_flags", None)
        if check_flags is not None:
            check_flags(early_values, [a.split("=", 1)[0] for a in args if a.startswith("--")])
    columns, defaults = [], {}
    for f in fields:
        if f.name in nested:
            group, instance = nested[f.name]
            flags_cls, default = _nested_flags(instance, group)
            values = stored.get(f.name) or {}
            known = {g.name for g in dataclasses.fields(flags_cls)}
            default = dataclasses.replace(default, **{k: _tuples(v) for k, v in values.items() if k in known})
            group_kind: Any = Annotated[(flags_cls, tyro.conf.OmitArgPrefixes, tyro.conf.arg(name=group))]
            columns.append((f.name, group_kind, dataclasses.field(default_factory=functools.partial(_same, default))))
            defaults[f.name] = default
            continue
        if f.metadata.get("nested"):
            continue  # nested settings this class gives none of here
        meta = f.metadata
        kind = _annotated(hints[f.name], meta.get("help", ""), f.name, meta.get("choices"), meta.get("shown_default"))
        columns.append((f.name, kind, dataclasses.field(default=f.default)))
        defaults[f.name] = _tuples(stored.get(f.name, f.default))
    flags = dataclasses.make_dataclass(cls.__name__, columns)
    about = (description or (cls.__doc__ or "").strip().splitlines()[0]) + CONFIG_HELP
    parsed = _run_tyro(flags, flags(**defaults), args, prog, about)
    values = {name: getattr(parsed, name) for name, _, _ in columns}
    for name, value in values.items():
        if name in nested:
            values[name] = _build_nested(type(nested[name][1]), dataclasses.asdict(value))
        elif isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"{flag_of(name)}: must be a finite number, got {value}")
    return cls(**values)


def _same(value: Any) -> Any:
    return value


def _tuples(value: Any) -> Any:
    """A JSON list read back as the tuple a setting holds."""
    return tuple(value) if isinstance(value, list) else value


def _build_nested(cls: type, values: Mapping[str, Any]) -> Any:
    """``cls(**values)``; its refusal (a ``ValueError`` naming a field) as a :class:`ConfigError` naming the flag."""
    for name, value in values.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"{flag_of(name)}: must be a finite number, got {value}")
    try:
        return cls(**values)
    except ValueError as exc:
        message = " ".join(str(exc).split())
        named = [name for name in values if re.search(rf"\b{name}\b", message)]
        first = min(named, key=lambda name: re.search(rf"\b{name}\b", message).start()) if named else None  # type: ignore[union-attr]
        if first is not None and message.startswith(f"{first} must "):  # the settings' rule: "<field> must ..."
            message = message.removeprefix(f"{first} ")
        raise ConfigError(f"{flag_of(first)}: {message}" if first else message) from None


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
        raise ConfigError(f"{flag_of(field_name)}: {message}")
