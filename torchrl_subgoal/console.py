"""The ``torchrl-subgoal`` command: ``studio`` (the subgoal studio) and ``report`` (a sweep's report)."""

from __future__ import annotations

import sys
from collections.abc import Sequence

__all__ = ["main"]

USAGE = """usage: torchrl-subgoal {studio,report} [options]

  studio   draw subgoal series on the map, save subgoal files, try them (a web page)
  report   write report.md, summary.json and plots for a sweep's results directory

'torchrl-subgoal COMMAND --help' tells more."""


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch to a subcommand; unknown ones get the usage and exit code 2.

    Examples:
        >>> main(["--help"])
        usage: torchrl-subgoal {studio,report} [options]
        ...
        0
    """
    args = list(sys.argv[1:] if argv is None else argv)
    command, rest = (args[0], args[1:]) if args else ("", [])
    if command == "studio":
        from torchrl_subgoal.studio import main as studio

        return studio(rest)
    if command == "report":
        from torchrl_subgoal.experiments.report import main as report

        return report(rest)
    if command in ("-h", "--help"):
        print(USAGE)
        return 0
    print(USAGE if not command else f"error: unknown command {command!r}\n{USAGE}", file=sys.stderr)
    return 2
