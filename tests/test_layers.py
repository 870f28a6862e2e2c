"""Folders are layers, and imports run downward only.

Each folder of the package names the folders it may import (`ALLOWED`, lowest layer first); a module may import
modules of its own folder and of the folders its folder allows, nothing else. The import graph is read from the
source (every import, at module level or inside a function: an import hidden in a function to dodge a cycle is
still a cycle); it must have no cycle. Each layer is also imported on its own in a fresh interpreter.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys

import pytest

from tests.conftest import ROOT

PACKAGE = ROOT / "vehid_cli"

# What each folder may import, lowest layer first (docs/architecture.md draws the same). A folder's modules may
# always import each other (without a cycle).
ALLOWED: dict[str, frozenset[str]] = {}
for _folder, _below in (
    ("core", ()),  # errors, atomic files, the HDF5 store, provenance, progress, interrupt, locks, seed streams, units
    ("io", ("core",)),  # files: the measurement CSV, logger formats (one module each), writers
    ("optimizers", ("core",)),  # one fixed outer loop, one module per algorithm
    ("models", ("core",)),  # pure physics: the car, the damper, effects (one module each), sensors, road, noise
    ("sim", ("core", "models")),  # the compiled kernel (imports no model), solvers, adapters
    ("config", ("core", "io", "models", "optimizers")),  # validated configs: a section module per system
    ("identify", ("core", "io", "models", "optimizers", "sim", "config")),  # task, objectives, bound, records
    ("diagnose", ("core", "io", "models", "optimizers", "sim", "config", "identify")),  # the generic loop
    ("systems", ("core", "io", "models", "optimizers", "sim", "config", "identify", "diagnose")),  # the seam
    ("campaign", ("core", "io", "models", "optimizers", "sim", "config", "identify", "systems")),  # runs, files
    ("design", ("core", "io", "models", "optimizers", "sim", "config", "identify", "systems", "campaign")),
    ("report", ("core", "io", "config", "identify", "systems", "campaign", "design")),  # tables and figures
    ("cli", ("core", "io", "config", "identify", "systems", "campaign", "design", "report")),  # the commands
):
    ALLOWED[_folder] = frozenset(_below)
ROOT_MODULES = {"__init__": frozenset({"core"}), "__main__": frozenset({"cli"})}  # the package root: at most three
# (the root __init__ sets process-wide settings before anything runs: BLAS threads, core/allocator.py)


def folder_of(module: str) -> str:
    """The layer (folder) of a module name relative to the package; the root's own modules are their own."""
    head = module.split(".")[0]
    if module in ROOT_MODULES or head in ALLOWED:
        return module if module in ROOT_MODULES else head
    raise AssertionError(f"vehid_cli.{module} is in no layer of tests/test_layers.py: place it")


def allowed(source: str, target: str) -> bool:
    """May module `source` import module `target`?"""
    a, b = folder_of(source), folder_of(target)
    if b == "__init__" or a == b:
        return True
    rules = ROOT_MODULES.get(a, ALLOWED.get(a, frozenset()))
    return b in rules


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
        f"{m} ({folder_of(m)}/) imports {t} ({folder_of(t)}/), which {folder_of(m)}/ may not import"
        for m, targets in graph().items()
        for t in sorted(targets)
        if not allowed(m, t)
    ]
    assert not wrong, "imports against the layers:\n" + "\n".join(wrong)


def test_the_package_root_keeps_at_most_three_modules():
    modules = sorted(p.stem for p in PACKAGE.glob("*.py") if p.stem not in ("__init__", "__main__"))
    assert len(modules) <= 3, modules


def test_the_checker_refuses_an_upward_import():
    """A model importing the config, or the kernel importing a system, breaks the rule (this test could not fail
    otherwise)."""
    assert not allowed("models.fullcar", "config.vehicle")
    assert not allowed("sim.kernel", "systems.base")
    assert not allowed("core.errors", "io.csv")
    assert allowed("systems.vehicle.system", "identify.task")
    assert allowed("cli.app", "campaign.runner")


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
        ("core", ("io", "models", "config", "sim", "identify", "systems", "campaign", "report", "cli")),
        ("io", ("models", "config", "sim", "identify", "systems", "campaign", "report", "cli")),
        ("models", ("config", "sim", "identify", "cli", "systems", "campaign", "report")),
        ("sim", ("config", "identify", "cli", "systems", "campaign", "report")),
        ("config", ("sim", "identify", "cli", "systems", "campaign", "report")),
        ("identify", ("diagnose", "systems", "campaign", "report", "cli")),
        ("systems", ("campaign", "design", "report", "cli")),
        ("campaign", ("design", "report", "cli")),
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


# ------------------------------------------------------------------------------------------ one home per concept

MAX_FILE_LINES = 600
MAX_FUNCTION_LINES = 80


def _compiled(node) -> bool:
    """A function numba compiles (decorated with njit or jit): a hot loop, which may stay whole."""
    for d in getattr(node, "decorator_list", ()):
        text = ast.unparse(d)
        if "njit" in text or "numba.jit" in text:
            return True
    return False


def long_functions(tree: ast.AST) -> list[tuple[str, int]]:
    """(name, lines) of every function over MAX_FUNCTION_LINES, not counting the compiled functions it holds."""
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) or _compiled(node):
            continue
        inner = sum(
            n.end_lineno - n.lineno + 1
            for n in ast.walk(node)
            if n is not node and isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and _compiled(n)
        )
        size = node.end_lineno - node.lineno + 1 - inner
        if size > MAX_FUNCTION_LINES:
            out.append((node.name, size))
    return out


def test_no_file_over_600_lines_and_no_function_over_80():
    big = [f"{p.relative_to(ROOT)}: {n} lines" for p in PACKAGE.rglob("*.py") if (n := len(p.read_text().splitlines()))
           > MAX_FILE_LINES]  # fmt: skip
    long = [f"{p.relative_to(ROOT)}: {name} {n} lines" for p in PACKAGE.rglob("*.py")
            for name, n in long_functions(ast.parse(p.read_text()))]  # fmt: skip
    assert not big and not long, "\n".join(big + long)


def test_the_size_check_sees_a_long_function_but_not_a_compiled_loop():
    body = "\n".join(f"    x{i} = {i}" for i in range(90))
    assert long_functions(ast.parse(f"def f():\n{body}\n")) == [("f", 91)]
    assert long_functions(ast.parse(f"@numba.njit\ndef f():\n{body}\n")) == []
    nested = "\n".join(f"        x{i} = {i}" for i in range(90))
    factory = f"def make():\n    @numba.njit(cache=True)\n    def f():\n{nested}\n    return f\n"
    assert long_functions(ast.parse(factory)) == []


# A check that asks which system a config or a result is: only systems/ (and the config registry) may hold one.
SYSTEM_CHECK = re.compile(
    r"isinstance\([^)]*\b(Config|DamperConfig|VehicleSystem|DamperSystem)\b"
    r"|\bsystem\s*[!=]=\s*[\"']|[\"'](vehicle|damper)[\"']\s*[!=]="
    r"|[!=]=\s*[\"'](vehicle|damper)[\"']"
)


def system_checks(text: str) -> list[str]:
    return [line.strip() for line in text.splitlines() if SYSTEM_CHECK.search(line)]


def test_nothing_outside_systems_asks_which_system_it_holds():
    found = [
        f"{p.relative_to(ROOT)}: {line}"
        for p in PACKAGE.rglob("*.py")
        if p.relative_to(PACKAGE).parts[0] not in ("systems", "config")
        for line in system_checks(p.read_text())
    ]
    assert not found, "\n".join(found)


def test_the_system_check_finder_sees_each_kind():
    for line in ('if campaign.system == "vehicle":', "if isinstance(cfg, DamperConfig):", 'x = c.system != "damper"',
                 'if "damper" == kind:'):  # fmt: skip
        assert system_checks(line), line
    assert not system_checks("system = system_class(cfg)")
