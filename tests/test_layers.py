"""Imports flow one way: errors/io <- models <- sim <- config <- systems <- campaign <- report <- cli.

The import graph is read from the source (every import, at module level or inside a function: an import hidden
in a function to dodge a cycle is still a cycle); it must have no cycle, and no module may import one of a
higher layer. Each layer is also imported on its own in a fresh interpreter.
"""

from __future__ import annotations

import ast
import subprocess
import sys

import pytest

from tests.conftest import ROOT

PACKAGE = ROOT / "vehid_cli"

# Lowest first; a module may import modules of its own layer or of lower ones. Keys are module names relative to
# the package (a package's __init__ is the package's name); a prefix ending in "." covers a subpackage.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("__init__", "errors", "provenance", "locking", "progress", "interrupt"),  # foundations
    # files (logger files read and written), bench motions, noise, solvers
    ("data", "h5io", "bench", "logger", "logger_write", "noise", "optimizers", "optimizers."),
    ("models", "models."),  # force laws and matrices: own their parameter tables and defaults
    ("sim", "sim."),  # the generic kernel and the car/bench adapters beside it
    ("config", "config."),  # validated configs: one module per system around a shared identify
    ("road", "experiment", "measured", "objectives", "crlb", "identification", "damper_fit"),  # a config made concrete
    ("records",),  # run records, summaries, campaigns: plain data
    ("systems", "systems."),  # the seam: the car and the damper bench
    ("results", "executor"),  # campaign files; where runs execute
    ("campaign", "sweep", "design"),  # the runner; families of campaigns; test design (bounds and campaigns)
    ("diagnose", "diagnose."),  # the closed loop
    ("report", "report."),  # tables and figures
    ("cli", "__main__"),  # the command line
)


def layer_of(module: str) -> int:
    for rank, members in enumerate(LAYERS):
        if any(module == m or (m.endswith(".") and module.startswith(m)) for m in members):
            return rank
    raise AssertionError(f"vehid_cli.{module} is in no layer of tests/test_layers.py: place it")


def module_name(path) -> str:
    rel = path.relative_to(PACKAGE).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" and len(rel.parts) > 1 else rel.parts
    return ".".join(parts)


def imports_of(path) -> set[str]:
    """The package modules a source file imports (relative or absolute), wherever the import statement is."""
    me = module_name(path)
    package = me.split(".") if path.name == "__init__.py" else me.split(".")[:-1]
    if path.name == "__init__.py" and me == "__init__":
        package = []
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)] if node.level > 1 else package
                target = ".".join(base + ([node.module] if node.module else []))
            elif node.module and node.module.startswith("vehid_cli"):
                target = node.module.removeprefix("vehid_cli").lstrip(".")
            else:
                continue
            candidates = [f"{target}.{a.name}" if target else a.name for a in node.names] + [target or "__init__"]
            found.update(c for c in candidates if resolves(c))
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("vehid_cli"):
                    name = a.name.removeprefix("vehid_cli").lstrip(".") or "__init__"
                    if resolves(name):
                        found.add(name)
    found.discard(me)
    return found


def resolves(name: str) -> bool:
    if name == "__init__":
        return True
    path = PACKAGE.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def graph() -> dict[str, set[str]]:
    return {module_name(p): imports_of(p) for p in sorted(PACKAGE.rglob("*.py"))}


def test_no_module_imports_a_higher_layer():
    wrong = [
        f"{m} (layer {layer_of(m)}) imports {t} (layer {layer_of(t)})"
        for m, targets in graph().items()
        for t in sorted(targets)
        if layer_of(t) > layer_of(m)
    ]
    assert not wrong, "imports against the layers:\n" + "\n".join(wrong)


def test_the_import_graph_has_no_cycle():
    g = graph()
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []
    cycles: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in sorted(g.get(m, ())):
            if state.get(t) == 1:
                cycles.append(" -> ".join(stack[stack.index(t) :] + [t]))
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(g):
        if m not in state:
            visit(m)
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_the_checker_sees_a_cycle_hidden_in_a_function(tmp_path, monkeypatch):
    """The graph reader must not be blind to function-level imports (the test above could not fail otherwise)."""
    src = tmp_path / "vehid_cli"
    (src / "models").mkdir(parents=True)
    (src / "__init__.py").write_text("")
    (src / "config.py").write_text("from .models import fullcar\n")
    (src / "models" / "__init__.py").write_text("")
    (src / "models" / "fullcar.py").write_text("def f():\n    from ..config import X\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", src)
    g = graph()
    assert "config" in g["models.fullcar"] and "models.fullcar" in g["config"]


@pytest.mark.parametrize(
    "layer, forbidden",
    [
        ("models", ("config", "sim", "cli", "systems", "campaign", "report", "results")),
        ("sim", ("config", "cli", "systems", "campaign", "report")),
        ("config", ("sim", "cli", "systems", "campaign", "report", "results")),
        ("systems", ("campaign", "report", "cli", "results")),
        ("campaign", ("report", "cli")),
        ("report", ("cli",)),
        ("cli", ()),
    ],
)
def test_each_layer_imports_alone_and_pulls_in_nothing_above_it(layer, forbidden):
    code = (
        f"import sys, vehid_cli.{layer}; print(' '.join(sorted(m for m in sys.modules if m.startswith('vehid_cli.'))))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    loaded = {m.removeprefix("vehid_cli.").split(".")[0] for m in res.stdout.split()}
    assert not loaded & set(forbidden), f"import vehid_cli.{layer} loads {sorted(loaded & set(forbidden))}"
