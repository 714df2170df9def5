"""The package layout as an architecture (docs/design.md, "Layers"): every import, lazy and
annotation-only ones included, runs down the layers, no two modules import each other (directly or round a cycle), the plants
in ``tasks/`` depend only on the seam, and nothing in the installed packages is there for the
tests alone."""

import ast
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("snn_torch", "evolution", "tasks")
LAYER = {"snn_torch": 0, "evolution": 1, "tasks": 2}


def _modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()


def _absolute(name: str, path: Path, node: ast.ImportFrom) -> str | None:
    """The module a ``from`` import names, relative imports resolved against ``name``'s package."""
    if node.level == 0:
        return node.module
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    base = package[:len(package) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(name: str, path: Path) -> set[str]:
    """The package modules ``name`` imports anywhere in its code: at the top, inside functions and
    under ``if TYPE_CHECKING:`` (an annotation-only import still ties the two modules together).
    ``from pkg import sub`` counts as ``pkg.sub`` where ``sub`` is a module; a package's
    ``__init__`` is not counted as a target (each submodule would otherwise close a cycle)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and (module := _absolute(name, path, node)):
            targets = [f"{module}.{a.name}" if f"{module}.{a.name}" in MODULES else module for a in node.names]
        else:
            continue
        for t in targets:
            if t.split(".")[0] in PACKAGES and t in MODULES and not MODULES[t].name == "__init__.py" and t != name:
                found.add(t)
    return found


GRAPH = nx.DiGraph([(m, t) for m, p in MODULES.items() for t in _imports(m, p)])


def test_no_import_cycles():
    cycles = sorted((c + c[:1] for c in nx.simple_cycles(GRAPH)), key=len)
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles[:5])


def test_the_cycle_check_sees_annotation_only_imports(tmp_path):
    # select.py once imported speciate under TYPE_CHECKING while speciate imported select: a
    # cycle the check must count.
    path = tmp_path / "m.py"
    path.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from evolution.speciate import x\n"
                    "def f():\n    from . import select\n")
    assert _imports("evolution.kernels.m", path) == {"evolution.speciate", "evolution.kernels.select"}


def test_imports_run_down_the_layers():
    upward = [(a, b) for a, b in GRAPH.edges if LAYER[b.split(".")[0]] > LAYER[a.split(".")[0]]]
    assert not upward, f"imports from a higher layer: {upward}"


@pytest.mark.parametrize("plant", sorted(m for m in MODULES if m.count(".") == 1 and m.startswith("tasks.")))
def test_a_plant_depends_only_on_the_seam(plant):
    allowed = {"evolution.task"}
    for target in GRAPH.successors(plant) if plant in GRAPH else []:
        package = target.split(".")[0]
        ok = (target in allowed or target.startswith("snn_torch.functional.")
              or (package == "tasks" and target.count(".") == 1))  # another plant (the gymnasium adapter)
        assert ok, f"{plant} imports {target}: a plant should need only evolution.task and numerics"


def test_nothing_in_the_packages_is_for_the_tests_alone():
    test_only = [str(p.relative_to(ROOT)) for package in PACKAGES for p in (ROOT / package).rglob("*")
                 if "test" in p.name.lower()]
    assert not test_only, test_only
