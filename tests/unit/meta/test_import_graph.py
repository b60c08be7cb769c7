"""The architecture, checked: import-linter's contracts (in pyproject.toml: imports go recorder ->
archive -> api -> the ``thermcap`` facade, never back; the recorder's inner order; no cycle
between siblings), the installed names, and entry points only for third-party plugins."""

from __future__ import annotations

import ast
import subprocess
import sys
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
def test_no_old_top_level_names(module):
    bad = sorted(i for i in _imports(MODULES[module], module, top_level_only=False) if i.split(".")[0] in ROOMS)
    assert bad == [], f"{module} imports {bad}: the installed names are thermcap.recorder, thermcap.archive, ..."


def test_entry_points_only_for_plugins():
    users = sorted(m for m, p in MODULES.items() if "entry_points" in p.read_text())
    assert users == ["thermcap.cli"], users


def test_the_import_contracts_hold(tmp_path):
    """pyproject.toml's import-linter contracts: the rooms' order, the facade above them, the
    recorder's inner order, no cycle between siblings."""
    r = subprocess.run([sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command; "
                        "sys.exit(lint_imports_command())", "--no-cache"], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert "0 broken" in r.stdout


def test_a_broken_contract_is_caught(tmp_path):
    """The contracts are live: the same check on a config whose layers are upside down fails."""
    config = tmp_path / "upside_down.toml"
    config.write_text('[tool.importlinter]\nroot_package = "thermcap"\n\n[[tool.importlinter.contracts]]\n'
                      'name = "upside down"\ntype = "layers"\n'
                      'layers = ["thermcap.recorder", "thermcap.archive"]\n')
    r = subprocess.run([sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command; "
                        "sys.exit(lint_imports_command())", str(config), "--no-cache"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode != 0 and "BROKEN" in r.stdout
