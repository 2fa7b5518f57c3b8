"""The package's layers, read from the source: every import of a tolsynth module (at module level
or inside a function) points to the importer's own layer or a lower one, no two modules import
each other through any chain, the top level holds at most 12 modules and no module exceeds 600
lines.  The layers are listed bottom to top in ``LAYERS``; docs/architecture.md explains them."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "tolsynth"

#: bottom to top; a module may import modules of its own layer or of lower layers only
LAYERS = [
    "base",  # tolsynth/*.py other than __init__/__main__: errors, units, checks, progress, ...
    "probability",  # error shapes, Gaussian and exact probabilities: pure maths
    "model",  # what a robot model is and how a file, D-H table or URDF becomes one
    "kinematics",  # CasADi graphs, the Mechanism, inverse kinematics, batch evaluation
    "problem",  # the tolerance NLP and its result
    "solvers",  # IPOPT, SUMT + Powell, the exact-probability solver
    "analysis",  # Monte Carlo, worst pose, maps, contributions, certification
    "synthesis",  # synthesize, workspace, processes, Pareto, budget, sweeps, reproduce
    "io",  # tables, reports
    "api",  # tolsynth/__init__.py
    "cli",  # the command line
]


def _modules() -> dict[str, Path]:
    out = {}
    for f in ROOT.rglob("*.py"):
        parts = f.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = f
    return out


def _layer(name: str) -> str:
    parts = name.split(".")
    if name == "tolsynth":
        return "api"
    if len(parts) == 2 and not (ROOT / parts[1]).is_dir():
        return "cli" if parts[1] == "__main__" else "base"
    return parts[1]


def _imports(name: str, path: Path, modules) -> set[str]:
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in modules else mod for a in node.names]
        for t in targets:
            while t and t not in modules:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found


MODULES = _modules()
GRAPH = {name: _imports(name, path, MODULES) for name, path in MODULES.items()}


def test_every_module_sits_in_a_known_layer():
    assert {_layer(m) for m in MODULES} <= set(LAYERS)


def test_no_upward_import():
    rank = {layer: i for i, layer in enumerate(LAYERS)}
    upward = sorted(f"{a} -> {b}" for a, deps in GRAPH.items() for b in deps if rank[_layer(b)] > rank[_layer(a)])
    assert upward == []


def test_no_import_cycle():
    # a package's __init__ importing its own submodules is not a cycle of the code's logic
    graph = {a: {b for b in deps if not a.startswith(b + ".")} for a, deps in GRAPH.items()}
    state: dict[str, int] = {}
    cycles = []

    def visit(node, stack):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(" -> ".join(stack[stack.index(nxt) :] + [nxt]))
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [])
    assert cycles == []


def test_top_level_is_small():
    top = sorted(p.name for p in ROOT.glob("*.py"))
    assert len(top) <= 12, top


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_module_over_600_lines(name):
    lines = len(MODULES[name].read_text().splitlines())
    assert lines <= 600, f"{name} has {lines} lines"


def test_the_checker_sees_a_planted_cycle_and_an_upward_import(tmp_path):
    # the checker's own check: a cycle and an upward import, planted, are both found
    pkg = tmp_path / "tolsynth"
    (pkg / "model").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "model" / "__init__.py").write_text("")
    (pkg / "model" / "a.py").write_text("def f():\n    from tolsynth.model import b\n")
    (pkg / "model" / "b.py").write_text("from .a import f\nfrom tolsynth.io import t\n")
    (pkg / "io").mkdir()
    (pkg / "io" / "__init__.py").write_text("")
    (pkg / "io" / "t.py").write_text("")
    mods = {}
    for f in pkg.rglob("*.py"):
        parts = f.relative_to(tmp_path).with_suffix("").parts
        mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    g = {n: _imports(n, p, mods) for n, p in mods.items()}
    assert "tolsynth.model.b" in g["tolsynth.model.a"] and "tolsynth.model.a" in g["tolsynth.model.b"]
    assert "tolsynth.io.t" in g["tolsynth.model.b"]
