"""tools/griffe_sphinx_roles.py: the docstrings' Sphinx roles become references to the objects they name."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import griffe

TOOL = Path(__file__).resolve().parents[2] / "tools" / "griffe_sphinx_roles.py"
spec = importlib.util.spec_from_file_location("griffe_sphinx_roles", TOOL)
assert spec is not None and spec.loader is not None
roles = importlib.util.module_from_spec(spec)
sys.modules[spec.name] = roles
spec.loader.exec_module(roles)


def test_roles_resolve_in_the_scope_of_their_docstring() -> None:
    package = griffe.load("torchrl_subgoal", search_paths=[str(TOOL.parents[1])], extensions=None)
    cli = package["experiments.cli"]
    text = roles.rewrite(cli, "a :class:`ConfigError`, :func:`~torchrl_subgoal.load_patterns()` and :meth:`nowhere`")
    assert '<autoref identifier="torchrl_subgoal.experiments.cli.ConfigError" optional><code>ConfigError</code>' in text
    assert '<autoref identifier="torchrl_subgoal.load_patterns" optional><code>load_patterns</code>' in text
    assert text.endswith("<code>nowhere</code>")  # unknown: its name in code font, no link
    titled = roles.rewrite(package["experiments"], ":attr:`the chunk's seed <torchrl_subgoal.experiments.Chunk.seed>`")
    target = "torchrl_subgoal.experiments.Chunk.seed"
    assert titled == f'<autoref identifier="{target}" optional><code>the chunk\'s seed</code></autoref>'


def test_the_extension_rewrites_every_docstring_of_the_package() -> None:
    extensions = griffe.load_extensions(f"{TOOL}:SphinxRoles")
    package = griffe.load("torchrl_subgoal", search_paths=[str(TOOL.parents[1])], extensions=extensions)
    left = [
        obj.path
        for obj in roles._objects(package)
        if obj.docstring is not None and roles.ROLE.search(obj.docstring.value)
    ]
    assert not left, left[:10]
    assert "<autoref" in package["experiments.cli.parse_config"].docstring.value
