"""A Griffe extension for the documentation site: Sphinx roles in docstrings become code.

The packages' docstrings cross-reference with Sphinx roles (``:class:`Policy```,
``:func:`~naruto_gym.scenes.resolve_scene```). mkdocstrings renders docstrings as Markdown,
where a role would show as literal text; this extension turns each role into an inline code
span holding the name as Sphinx shows it (only the last component after ``~``). Loaded by
``mkdocs.yml`` (``plugins: mkdocstrings: handlers: python: options: extensions``).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:attr|class|const|data|exc|func|meth|mod|obj):`([^`]+)`")


def _as_code(match: re.Match[str]) -> str:
    """The code span of one role: its title, or its target (shortened after ``~``)."""
    text = match.group(1)
    title, _, target = text.partition(" <")
    if target:  # :class:`title <target>`
        return f"`{title.strip()}`"
    if text.startswith("~"):
        text = text[1:].rsplit(".", 1)[-1]
    return f"`{text.lstrip('.')}`"


def roles_as_code(docstring: str) -> str:
    """``docstring`` with every Sphinx role replaced by an inline code span."""
    return _ROLE.sub(_as_code, docstring)


class SphinxRolesAsCode(griffe.Extension):
    """Rewrites the docstring of every loaded object once the object tree is complete."""

    def on_object(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = roles_as_code(obj.docstring.value)
