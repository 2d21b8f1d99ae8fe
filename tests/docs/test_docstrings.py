"""Every public class and function of the package has a docstring with a runnable example.

The examples run as doctests (``--doctest-modules`` in pyproject.toml). A new
public name needs an ``Examples:`` block; ``WITHOUT_EXAMPLE`` (names exempted
while they lack one) is empty and may only stay so or shrink.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "torchrl_subgoal"

#: ``module.name`` of the public classes and functions without an example yet (see above)
WITHOUT_EXAMPLE: set[str] = set()


def _public() -> dict[str, str]:
    """``module.name`` -> docstring of every module-level public class and function."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if any(part.startswith("_") and part != "__init__.py" for part in path.relative_to(PACKAGE).parts):
            continue  # private modules and packages (the compiled kernels)
        if path.relative_to(PACKAGE).parts[0] == "recipes" and path.name != "__init__.py":
            continue  # the command's recipes: programs, run end to end by tests/recipes
        module = ".".join(path.relative_to(PACKAGE).with_suffix("").parts)
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef | ast.ClassDef) and not node.name.startswith("_"):
                found[f"{module}.{node.name}"] = ast.get_docstring(node) or ""
    return found


def test_public_names_have_runnable_examples() -> None:
    public = _public()
    lacking = {name for name, doc in public.items() if ">>>" not in doc}
    new = sorted(lacking - WITHOUT_EXAMPLE)
    assert not new, f"public names without an Examples: block (a short doctest): {new}"
    done = sorted(WITHOUT_EXAMPLE - lacking)
    assert not done, f"these now have an example or are gone: remove them from WITHOUT_EXAMPLE in {__file__}: {done}"
