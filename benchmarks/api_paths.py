"""Functions under the module paths of the current and the previous package layout.

The bitwise regressions (``soft_bitwise.py``, ``network_bitwise.py``) run one script
against two versions of jamflow; a function that moved between modules is looked up
where each version keeps it.
"""

from __future__ import annotations

import importlib
from typing import Any


def find(name: str, *modules: str) -> Any:
    """``name`` from the first of ``modules`` that imports and defines it."""
    for module in modules:
        try:
            found = importlib.import_module(module)
        except ImportError:
            continue
        if hasattr(found, name):
            return getattr(found, name)
    raise ImportError(f"{name} is in none of {', '.join(modules)}")
