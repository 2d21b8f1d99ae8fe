"""Subgoal studio: a web page to draw subgoal series on the map, save them, and try them.

Run ``torchrl-subgoal studio`` (or ``python -m torchrl_subgoal.studio``) and open
the address it prints. The page draws the four-rooms grid and the PinBall maps
from the package's environments; a person places ordered subgoals by clicking,
saves a subgoal file the recipes read (``--subgoals FILE``), and "Try it" runs
a short learning with the pattern against the unshaped baseline. See
``docs/studio.md``. Needs the ``web`` extra (Flask).

Modules: :mod:`~torchrl_subgoal.studio.server` (app, routes, command line),
:mod:`~torchrl_subgoal.studio.document` (requests to and from subgoal files),
:mod:`~torchrl_subgoal.studio.domains` (maps and bounds per domain),
:mod:`~torchrl_subgoal.studio.training` ("Try it"),
:mod:`~torchrl_subgoal.studio.jobs` (background learnings).
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Serve the studio (see :func:`torchrl_subgoal.studio.server.main`); a clear error without Flask.

    Examples:
        >>> main(["--max-jobs", "0"])  # a one-line error on stderr
        2
    """
    try:
        from torchrl_subgoal.studio.server import main as serve_main
    except ImportError as exc:
        import sys

        print(
            f"error: the studio needs Flask ({exc}); install it with: pip install 'torchrl_subgoal[web]'",
            file=sys.stderr,
        )
        return 2
    return serve_main(argv)
