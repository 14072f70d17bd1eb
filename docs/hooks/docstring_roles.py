"""mkdocs hook: the cross-reference roles of the docstrings (``:class:`SheathModel```) read as code in the API
reference.

The library's docstrings use numpydoc with Sphinx roles (``:mod:``, ``:class:``, ``:func:``, ``:meth:``,
``:attr:``, ``:data:``, ``:exc:``); mkdocstrings renders the role's name as text before the code span. This hook
drops that text, leaving the code span, on every page.
"""
from __future__ import annotations

import re
from typing import Any

_ROLE = re.compile(r":(?:mod|class|func|meth|attr|data|exc|obj|const):(?=<code>)")


def on_page_content(html: str, **kwargs: Any) -> str:
    """The page's HTML with each role's text before a code span removed."""
    return _ROLE.sub("", html)
