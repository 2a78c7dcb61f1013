"""The house rules (docs/concepts.md), checked on the source: the axis packages import only the core's public
interface (``taslel_bench.interfaces``, ``taslel_bench.api``) and never each other; the core never imports
an axis package, a study or a test; inside the core no module imports one that imports it back."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
AXES = ("scenarios", "solvers", "estimators")
PUBLIC = ("taslel_bench.interfaces", "taslel_bench.api")


def _imports(path: Path) -> list[str]:
    """Every module an ``import``/``from ... import`` in ``path`` names (function bodies included); for
    ``from package import name`` also ``package.name``."""
    tree = ast.parse(path.read_text())
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append(node.module)
            out += [f"{node.module}.{a.name}" for a in node.names]
    return out


def _module(path: Path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")


@pytest.mark.parametrize("axis", AXES)
def test_an_axis_package_imports_only_the_public_interface(axis):
    wrong = []
    for path in sorted((ROOT / axis).rglob("*.py")):
        for name in _imports(path):
            top = name.split(".")[0]
            if (
                top == "taslel_bench"
                and name != "taslel_bench"
                and not name.startswith(PUBLIC)
                or top in AXES
                and top != axis
                or top in ("studies", "tests")
            ):
                wrong.append(f"{path.relative_to(ROOT)}: {name}")
    assert not wrong


def test_the_core_never_imports_an_axis_a_study_or_a_test():
    wrong = [f"{p.relative_to(ROOT)}: {n}" for p in sorted((ROOT / "taslel_bench").rglob("*.py"))
             for n in _imports(p) if n.split(".")[0] in (*AXES, "studies", "tests")]
    assert not wrong


def test_the_core_has_no_import_cycles():
    modules = {_module(p): p for p in (ROOT / "taslel_bench").rglob("*.py")}
    graph = {m: {n for n in _imports(p) if n in modules and n != m} for m, p in modules.items()}
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    cycles = []

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                cycles.append(" -> ".join([*path[path.index(n):], n]))
            elif n not in state:
                visit(n, [*path, n])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not cycles
