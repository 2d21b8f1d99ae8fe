"""The error every malformed subgoal file or pattern raises, and where it points."""

from __future__ import annotations


class SubgoalFileError(ValueError):
    """A subgoal file or pattern is malformed; the message names file, pattern and field.

    Examples:
        >>> from torchrl_subgoal import SubgoalSeries
        >>> try:
        ...     SubgoalSeries([], name="mine", source="f.yaml")
        ... except SubgoalFileError as error:
        ...     print(error)
        f.yaml: pattern 'mine': a pattern needs at least one subgoal
    """


def _where(source: str | None, pattern: str | None, field_: str) -> str:
    parts = [source or "<subgoals>"]
    if pattern is not None:
        parts.append(f"pattern {pattern!r}")
    if field_:
        parts.append(field_)
    return ": ".join(parts)
