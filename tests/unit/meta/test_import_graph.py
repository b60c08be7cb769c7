"""The architecture, checked: imports go recorder -> archive -> api -> the ``thermcap`` facade,
never back (the facade fills the lower rooms' registries), no import cycle exists (at module level
or inside functions), and no module of ours uses entry points but for third-party plugins."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
ROOMS = ["recorder", "archive", "api"]
ORDER = [*ROOMS, "facade"]


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in ROOMS:
        for path in (ROOT / pkg).rglob("*.py"):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
            out[".".join(["thermcap", *parts])] = path
    for path in (ROOT / "thermcap").glob("*.py"):  # the facade's own modules (the rooms are links)
        out["thermcap" if path.stem == "__init__" else f"thermcap.{path.stem}"] = path
    return out


def _room(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "thermcap" and parts[1] in ROOMS else "facade"


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


def _ours(name: str) -> bool:
    return name == "thermcap" or name.startswith("thermcap.")


def test_the_packages_are_found():
    assert {_room(m) for m in MODULES} == set(ORDER)
    assert len(MODULES) > 60


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_import_from_a_later_package(module):
    rank = ORDER.index(_room(module))
    later = ORDER[rank + 1:]
    bad = sorted(i for i in _imports(MODULES[module], module, top_level_only=False)
                 if _ours(i) and _room(i) in later and i != "thermcap")
    assert bad == [], f"{module} imports {bad}: data and imports flow recorder -> archive -> api -> thermcap"


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_old_top_level_names(module):
    bad = sorted(i for i in _imports(MODULES[module], module, top_level_only=False) if i.split(".")[0] in ROOMS)
    assert bad == [], f"{module} imports {bad}: the installed names are thermcap.recorder, thermcap.archive, ..."


def test_entry_points_only_for_plugins():
    users = sorted(m for m, p in MODULES.items() if "entry_points" in p.read_text())
    assert users == ["thermcap.cli"], users


@pytest.mark.parametrize("top_level_only", [True, False], ids=["module-level", "any-level"])
def test_no_import_cycle(top_level_only):
    graph = {m: {i for i in _imports(p, m, top_level_only=top_level_only) if i in MODULES and i != m}
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
