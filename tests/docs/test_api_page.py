"""docs/api.md shows the public API exactly: ``torchrl_subgoal.__all__`` and each documented module's."""

from __future__ import annotations

import importlib
import re
from pathlib import Path
from types import ModuleType
from typing import Any

import torchrl_subgoal

API = Path(__file__).resolve().parents[2] / "docs" / "api.md"


def entries() -> list[tuple[str, list[str] | None]]:
    """Each ``::: target`` of the page, with its ``members:`` list when it gives one."""
    found: list[tuple[str, list[str] | None]] = []
    for block in re.split(r"^(?=::: )", API.read_text(), flags=re.M)[1:]:
        target = block.split()[1]
        listed = re.search(r"members:\n((?:\s+- \S+\n)+)", block)
        found.append((target, re.findall(r"- (\S+)", listed.group(1)) if listed else None))
    return found


def resolve(target: str) -> Any:
    try:
        return importlib.import_module(target)
    except ModuleNotFoundError:
        module, _, name = target.rpartition(".")
        return getattr(importlib.import_module(module), name)


def test_every_entry_resolves_and_every_module_declares_its_public_names() -> None:
    undeclared = [t for t, _ in entries() if isinstance(resolve(t), ModuleType) and not hasattr(resolve(t), "__all__")]
    assert not undeclared, f"give these modules an __all__ (what the page shows): {undeclared}"
    for target, _ in entries():
        module = resolve(target)
        if isinstance(module, ModuleType):
            assert all(hasattr(module, name) for name in module.__all__), target


def test_no_entry_is_shown_twice() -> None:
    targets = [t for t, _ in entries()]
    assert len(targets) == len(set(targets))
    assert targets[0] == "torchrl_subgoal"


def test_a_member_list_shows_what_the_facade_does_not() -> None:
    """A module shown by a list of members: every public name of it is on the list or, the same
    object, in ``torchrl_subgoal.__all__``; nothing else is on the list."""
    for target, members in entries():
        if members is None:
            continue
        module = resolve(target)
        assert set(members) <= set(module.__all__), target
        facade = {n for n in torchrl_subgoal.__all__ if getattr(module, n, None) is getattr(torchrl_subgoal, n)}
        assert set(module.__all__) - set(members) <= facade, f"{target}: add to its members"
