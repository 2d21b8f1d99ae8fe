"""Docs build extension: the docstrings' Sphinx cross-reference roles rendered as links in the API reference.

The docstrings write references the way Python's own docs do (``:class:`SubgoalSeries```,
``:func:`~torchrl_subgoal.load_patterns```, ``:meth:`advance```), which a reader of the source
and ``help()`` reads as they are. mkdocstrings renders Markdown, where such a role would show as
literal text; this Griffe extension (``mkdocs.yml`` loads it) rewrites each role, when the site
is built, into an autorefs reference to the object it names, resolved in the scope of the
docstring's object: a link where the site documents that object, its name in code font where it
does not (a private helper, another library's class). The sources are not changed.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import griffe

#: ``:role:`target```, ``:role:`~target``` (``~``: show the last part of the name only) or
#: ``:role:`title <target>```
ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|data|attr|exc|obj|const):`(~?)([^`<]*?)\s*(?:<([\w.]+)>)?`")


def _objects(obj: griffe.Object) -> Iterator[griffe.Object]:
    yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _objects(member)  # type: ignore[arg-type]


def resolve(scope: griffe.Object, target: str) -> str | None:
    """The full path of ``target`` (a dotted name) as seen from ``scope``, or ``None``."""
    root, *rest = target.split(".")
    if root == scope.package.name:
        return target
    try:
        path = scope.resolve(root)
    except (griffe.NameResolutionError, KeyError, ValueError, AttributeError):
        return None
    return ".".join([path, *rest])


def reference(scope: griffe.Object, short: bool, target: str, title: str | None = None) -> str:
    """The HTML autorefs turns into a link to ``target`` (plain code when the site has no page for it)."""
    target = target.removesuffix("()")
    title = title or (target.rsplit(".", 1)[-1] if short else target)
    path = resolve(scope, target) if re.fullmatch(r"[\w.]+", target) else None
    if path is None:
        return f"<code>{title}</code>"
    return f'<autoref identifier="{path}" optional><code>{title}</code></autoref>'


def rewrite(scope: griffe.Object, text: str) -> str:
    """``text`` with every role replaced by a :func:`reference`.

    Examples:
        >>> module = griffe.Module("pkg")
        >>> rewrite(module, "see :func:`~pkg.tools.run` and :class:`Missing`")
        'see <autoref identifier="pkg.tools.run" optional><code>run</code></autoref> and <code>Missing</code>'
        >>> rewrite(module, ":attr:`the seed <pkg.Chunk.seed>`")
        '<autoref identifier="pkg.Chunk.seed" optional><code>the seed</code></autoref>'
    """

    def replace(match: re.Match[str]) -> str:
        if match[3]:
            return reference(scope, False, match[3], match[2].strip())
        return reference(scope, bool(match[1]), match[2].strip())

    return ROLE.sub(replace, text)


class SphinxRoles(griffe.Extension):
    """Rewrite the roles of every docstring of a loaded package (see the module's docstring)."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        for obj in _objects(pkg):
            if obj.docstring is not None:
                scope = obj if obj.is_module or obj.is_class else (obj.parent or obj)
                obj.docstring.value = rewrite(scope, obj.docstring.value)
