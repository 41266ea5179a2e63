"""Griffe extension for the API pages: Sphinx roles in docstrings (:func:`x`, :class:`~a.B`, ...) become code spans.

roadload's docstrings use Sphinx cross-reference roles; mkdocstrings' Google-style parser would print them
verbatim. Loaded by mkdocs.yml (mkdocstrings -> python -> options -> extensions) from docs/tools/.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj|const):`~?([^`]+)`")


class SphinxRoles(griffe.Extension):
    """Rewrite ``:role:`target``` to ```target``` in every docstring."""

    def on_instance(self, *, node: Any, obj: griffe.Object, agent: Any, **kwargs: Any) -> None:
        if obj.docstring is not None and ":" in obj.docstring.value:
            obj.docstring.value = ROLE.sub(r"`\1`", obj.docstring.value)
