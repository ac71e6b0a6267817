"""Griffe extension for the API reference: Sphinx roles in docstrings become code spans.

jamflow's numpy-style docstrings cross-reference with Sphinx roles (``:func:`x```,
``:class:`~jamflow.Packing```), which MkDocs would print verbatim. This keeps the
referenced name, without the leading ``~`` (the short-name marker), as inline code.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|data|attr|mod|obj|exc|const):`~?([^`]+)`")


class SphinxRoles(griffe.Extension):
    """Rewrite ``:role:`target``` as ```target``` in every docstring."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = _ROLE.sub(r"`\1`", obj.docstring.value)
