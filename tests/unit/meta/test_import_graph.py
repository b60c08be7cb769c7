"""The architecture, checked: imports go recorder -> archive -> api only (entry points cross back),
and no module-level import cycle exists inside any package."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
ORDER = ["recorder", "archive", "api"]


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in ORDER:
        for path in (ROOT / pkg).rglob("*.py"):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
            out[".".join(parts)] = path
    return out


def _imports(path: Path, module: str, top_level_only: bool) -> set[str]:
    tree = ast.parse(path.read_text())
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    if top_level_only:  # an `if TYPE_CHECKING:` block imports nothing at run time
        nodes = [n for n in nodes if not (isinstance(n, ast.If) and "TYPE_CHECKING" in ast.dump(n.test))]
    found: set[str] = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the importing module's package
                base = module.split(".")[: -node.level if path.name != "__init__.py" else len(module.split("."))
                                          - node.level + 1]
                name = ".".join([*base, node.module] if node.module else base)
            else:
                name = node.module or ""
            found.add(name)
            found |= {f"{name}.{a.name}" for a in node.names}
    return found


MODULES = _modules()


def test_the_packages_are_found():
    assert {m.split(".")[0] for m in MODULES} == set(ORDER)
    assert len(MODULES) > 60


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_import_from_a_later_package(module):
    rank = ORDER.index(module.split(".")[0])
    later = ORDER[rank + 1:]
    bad = sorted(i for i in _imports(MODULES[module], module, top_level_only=False) if i.split(".")[0] in later)
    assert bad == [], f"{module} imports {bad}: data and imports flow recorder -> archive -> api"


def test_no_module_level_import_cycle():
    graph = {m: {i for i in _imports(p, m, top_level_only=True) if i in MODULES and i != m}
             for m, p in MODULES.items()}
    # a package's __init__ importing its own submodules is how a public face is built, not a cycle
    for m, deps in graph.items():
        graph[m] = {d for d in deps if not d.startswith(m + ".")}
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for d in sorted(graph[m]):
            if state.get(d) == 1:
                cycles.append([*stack[stack.index(d):], d])
            elif d not in state:
                visit(d)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    assert cycles == []
