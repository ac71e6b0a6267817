"""The import graph of ``src/jamflow`` follows the floors of the house (docs: DESIGN, "The house").

Every ``import`` and ``from ... import`` of the package's own modules, module-level or
inside functions, is read with ``ast`` (nothing is imported) and reduced to an arrow
between top-level parts (a subpackage such as ``network`` or a top-level module such
as ``box``). Parts sit on floors; a part may import only parts on lower floors, so
no two parts import each other and there is no circle. The ground modules may import
each other as long as they form no circle.

``io`` sits above ``network``: its exporters write network quantities (force-balance
residuals in extended XYZ). ``analysis`` is a leaf: only the top floor imports it.
"""

from __future__ import annotations

import ast
import functools
import graphlib
from pathlib import Path

import jamflow

SRC = Path(jamflow.__file__).resolve().parent

GROUND = ("box", "tolerances", "presets", "provenance", "highs", "_kernel_cache", "_numba", "stages", "resources")

#: floors from the ground up; a part imports only parts on floors below its own
FLOORS: tuple[tuple[str, ...], ...] = (
    GROUND,
    ("neighbors",),
    ("state",),
    ("network",),
    ("io",),
    ("minimize",),
    ("models",),
    ("protocols",),
    ("chains", "shapes"),
    ("analysis",),
    ("scenes",),
    ("plots", "summary", "tradeoff", "reproduce"),
    ("cli",),
    ("__main__",),
)
FLOOR = {part: level for level, parts in enumerate(FLOORS) for part in parts}


def _module_name(path: Path) -> tuple[str, str]:
    """Dotted name of a source file and the package its relative imports start from."""
    parts = ("jamflow",) + path.relative_to(SRC).with_suffix("").parts
    if parts[-1] == "__init__":
        parts = parts[:-1]
        return ".".join(parts), ".".join(parts)
    return ".".join(parts), ".".join(parts[:-1])


def _targets(node: ast.AST, package: str) -> list[str]:
    """Dotted names of the jamflow modules (or names in them) an import node reads."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if not isinstance(node, ast.ImportFrom):
        return []
    if node.level:
        base = package.split(".")[: len(package.split(".")) - node.level + 1]
        module = ".".join(base + ([node.module] if node.module else []))
    else:
        module = node.module or ""
    if module == "jamflow" or not node.module:
        # ``from jamflow import x`` / ``from . import x``: x may be a part
        return [f"{module}.{alias.name}" for alias in node.names]
    return [module]


def _part(dotted: str) -> str | None:
    """Top-level part of ``jamflow.<part>...``; None for the package root itself."""
    parts = dotted.split(".")
    return parts[1] if len(parts) > 1 else None


@functools.cache
def import_arrows() -> dict[tuple[str, str], list[str]]:
    """Arrows ``(importer, imported)`` between different parts, each with the places (file:line) that make it."""
    arrows: dict[tuple[str, str], list[str]] = {}
    for path in sorted(SRC.rglob("*.py")):
        name, package = _module_name(path)
        source = _part(name)
        if source is None:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            for target in _targets(node, package):
                if not (target == "jamflow" or target.startswith("jamflow.")):
                    continue
                dest = _part(target)
                if dest is None or dest == source or not (SRC / dest).exists() and not (SRC / f"{dest}.py").exists():
                    continue  # the package root, the part itself, or a name defined in jamflow/__init__.py
                place = f"{path.relative_to(SRC)}:{node.lineno}"
                arrows.setdefault((source, dest), []).append(place)
    return arrows


def test_the_graph_is_read() -> None:
    """The parser sees the arrows every layout has (a test that cannot fail otherwise)."""
    arrows = import_arrows()
    assert ("models", "minimize") in arrows and ("protocols", "network") in arrows
    assert ("cli", "analysis") in arrows
    assert len({part for arrow in arrows for part in arrow}) >= 20


def test_every_part_has_a_floor() -> None:
    parts = {p.stem if p.suffix == ".py" else p.name for p in SRC.iterdir()
             if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").exists()}
    unknown = sorted(parts - set(FLOOR))
    assert not unknown, f"parts without a floor in tests/test_house.py::FLOORS: {unknown}"


def test_no_part_imports_upward_or_sideways() -> None:
    arrows = import_arrows()
    bad = [f"{a} (floor {FLOOR[a]}) imports {b} (floor {FLOOR[b]}) at {', '.join(places[:3])}"
           for (a, b), places in sorted(arrows.items())
           if a in FLOOR and b in FLOOR and FLOOR[b] >= FLOOR[a] and not (FLOOR[a] == FLOOR[b] == 0)]
    assert not bad, "arrows against the floors:\n" + "\n".join(bad)


def test_no_circle_between_parts() -> None:
    arrows = import_arrows()
    graph: dict[str, set[str]] = {}
    for a, b in arrows:
        graph.setdefault(a, set()).add(b)
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as err:
        raise AssertionError(f"import circle between parts: {' -> '.join(err.args[1])}") from None


def test_only_the_top_floor_imports_analysis() -> None:
    arrows = import_arrows()
    importers = sorted({a for a, b in arrows if b == "analysis"})
    assert set(importers) <= {"cli", "plots", "summary", "tradeoff"}, importers


def test_the_documented_arrows() -> None:
    """The arrows the house names: minimisers never reach models, network never reaches
    models, minimisers or protocols, and state stands on the ground and neighbors alone."""
    arrows = import_arrows()
    assert not {b for a, b in arrows if a == "minimize"} & {"models", "protocols", "io"}
    assert not {b for a, b in arrows if a == "network"} & {"models", "minimize", "protocols", "io"}
    assert {b for a, b in arrows if a == "state"} <= set(GROUND) | {"neighbors"}
    assert {b for a, b in arrows if a == "neighbors"} <= set(GROUND)
