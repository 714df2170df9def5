"""The package layout as an architecture (docs/design.md, "Layers"): every import, lazy ones included,
runs down the layers, no two modules import each other (directly or round a cycle), the plants
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


def _type_checking_lines(tree: ast.Module) -> set[int]:
    """Lines inside ``if TYPE_CHECKING:`` blocks (annotations only: not imported at run time)."""
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", getattr(node.test, "attr", "")) == "TYPE_CHECKING":
            for child in node.body:
                lines.update(range(child.lineno, (child.end_lineno or child.lineno) + 1))
    return lines


def _imports(name: str, path: Path) -> set[str]:
    """The package modules ``name`` imports anywhere in its code (``from pkg import sub`` counts as
    ``pkg.sub`` where ``sub`` is a module; a package's ``__init__`` is not counted as a target)."""
    tree = ast.parse(path.read_text())
    skip = _type_checking_lines(tree)
    found = set()
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            targets = [f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in MODULES else node.module
                       for a in node.names]
        else:
            continue
        for t in targets:
            if t.split(".")[0] in PACKAGES and t in MODULES and not MODULES[t].name == "__init__.py" and t != name:
                found.add(t)
    return found


GRAPH = nx.DiGraph([(m, t) for m, p in MODULES.items() for t in _imports(m, p)])


def test_no_import_cycles():
    cycles = list(nx.simple_cycles(GRAPH))
    assert not cycles, f"import cycles: {sorted(cycles, key=len)[:5]}"


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
