"""The ``torchrl-subgoal`` command: ``train``, ``reproduce``, ``report`` and ``studio``.

Each subcommand is a module's ``main`` (the recipes of :mod:`torchrl_subgoal.recipes`, the report of
:mod:`torchrl_subgoal.experiments.report`, the studio's server), imported only when asked for, so
``torchrl-subgoal --help`` is instant and a missing extra is named instead of a traceback.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

from torchrl_subgoal.recipes import REPRODUCTIONS

__all__ = ["main"]

USAGE = """usage: torchrl-subgoal {train,reproduce,report,studio} [options]

  train      a TorchRL learner (A2C, PPO, DQN, DDPG) with subgoal shaping against the unshaped one,
             on a registered domain (torchrl-subgoal train --algo ppo --domain four_rooms_step)
  reproduce  a paper reproduction: four-rooms, pinball or pick-and-place
             (torchrl-subgoal reproduce four-rooms --learnings 100)
  report     write report.md, summary.json and figures for a results directory
  studio     draw subgoal series on a map, save subgoal files, try them (a web page)

'torchrl-subgoal COMMAND --help' tells more."""

#: subcommand -> (module, the extra its imports need)
COMMANDS = {
    "train": ("torchrl_subgoal.recipes.train", "experiments"),
    "report": ("torchrl_subgoal.experiments.report", "experiments"),
    "studio": ("torchrl_subgoal.studio", "web"),
}


def _run(module: str, extra: str, argv: list[str], prog: str) -> int:
    try:
        main = importlib.import_module(module).main
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.split(".")[0] == "torchrl_subgoal":
            raise
        print(
            f"error: {prog} needs the {extra} extra (missing: {exc.name}): pip install 'torchrl_subgoal[{extra}]'",
            file=sys.stderr,
        )
        return 2
    if module.startswith("torchrl_subgoal.recipes."):
        return int(main(argv, prog=prog))
    return int(main(argv))


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch to a subcommand; unknown ones get the usage and exit code 2.

    Examples:
        >>> main(["--help"])
        usage: torchrl-subgoal {train,reproduce,report,studio} [options]
        ...
        0
        >>> main(["reproduce", "cartpole"])  # prints "error: ... choose from four-rooms, ..." on stderr
        2
    """
    args = list(sys.argv[1:] if argv is None else argv)
    command, rest = (args[0], args[1:]) if args else ("", [])
    if command in COMMANDS:
        module, extra = COMMANDS[command]
        return _run(module, extra, rest, f"torchrl-subgoal {command}")
    if command == "reproduce":
        which, rest = (rest[0], rest[1:]) if rest else ("", [])
        if which in REPRODUCTIONS:
            prog = f"torchrl-subgoal reproduce {which}"
            return _run(f"torchrl_subgoal.recipes.{REPRODUCTIONS[which]}", "experiments", rest, prog)
        if which in ("-h", "--help"):
            print(f"usage: torchrl-subgoal reproduce {{{','.join(REPRODUCTIONS)}}} [options]")
            return 0
        problem = f"unknown reproduction {which!r}; " if which else "name a reproduction: "
        print(f"error: {problem}choose from {', '.join(REPRODUCTIONS)}", file=sys.stderr)
        return 2
    if command in ("-h", "--help"):
        print(USAGE)
        return 0
    print(USAGE if not command else f"error: unknown command {command!r}\n{USAGE}", file=sys.stderr)
    return 2
