"""The layering contract of the package, checked on every import the code makes, lazy ones included.

Every ``import``/``from ... import`` anywhere in a module (at the top, inside a function, under ``if``) and every
``import_module("...")`` with a literal name is an edge. Two rules:

1. **Layers** (:data:`LAYERS`, top to bottom): a module imports only from its own package or from packages of
   lower layers; packages of one layer are independent (neither imports the other).
2. **No cycles** between modules (any import counts, so a lazy import does not hide a cycle).

The contract fails on a deliberately wrong import (``test_the_contract_refuses_a_wrong_import``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: top to bottom; each entry a layer of independent packages (module prefixes)
LAYERS: list[tuple[str, ...]] = [
    ("ddmr_cli.cli",),                           # the command line and the Hydra glue
    ("ddmr_cli.report",),                        # reports, tables, figures, verdicts
    ("ddmr_cli.study",),                         # sensitivity study, tuning, calibration search
    ("ddmr_cli.job", "ddmr_cli.bench"),          # one job into its dir; benchmarks
    ("ddmr_cli.plots",),                         # figure primitives and a job's plots
    ("ddmr_cli.config",),                        # Hydra composition, schemas, validation, the sweep plan
    ("ddmr_cli.storage", "ddmr_cli.paper"),     # atomic writes, job dirs, locks, sweep state and tables; the paper
    ("ddmr_cli.engine",),                        # the step loop, metrics, results
    ("ddmr_cli.plant",),                         # the plants the engine steps
    ("ddmr_cli.control",),                       # the control laws
    ("ddmr_cli.model",),                         # robot, terrain, scenario, sensor, actuator, kinematics
    ("ddmr_cli.bit_generators",),                # numpy's PCG64 streams drawn by compiled code
    ("ddmr_cli.checks", "ddmr_cli.compiled", "ddmr_cli.workers", "ddmr_cli.compat", "ddmr_cli.version",
     "ddmr_cli.data", "ddmr_cli.progress", "ddmr_cli.keyed", "ddmr_cli.display", "ddmr_cli.exports"),
    ("ddmr_cli.errors",),
]
#: packages that are part of another: Hydra instantiates sweepers only from ``hydra_plugins``, so the config
#: package's sweeper (``hydra/sweeper=ddmr``) lives there
PART_OF = {"hydra_plugins": "ddmr_cli.config"}
#: the package's top-level API (``import ddmr_cli``) may use anything; nothing below imports it
API = "ddmr_cli"


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def source_modules() -> dict[str, Path]:
    files = [*ROOT.joinpath("ddmr_cli").rglob("*.py"), *ROOT.joinpath("hydra_plugins").rglob("*.py")]
    return {module_name(p): p for p in files if "conf" not in p.relative_to(ROOT).parts}


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """Every project module ``name`` imports, anywhere in its source."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)  # ``import a.b``: the edge is to a.b
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")
                parent = parent[:len(parent) - node.level + 1]
                base = ".".join([*parent, base] if base else parent)
            # ``from a import b``: to the submodule a.b when there is one, else to a (b is a name defined there)
            targets.update(f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names)
        elif (isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", None)) == "import_module"
              and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            targets.add(node.args[0].value)
    resolved = set()
    for target in targets:
        while target and target not in known:  # ``from a.b import c``: c may be a name, not a module
            target = target.rpartition(".")[0]
        if target and target != name:
            resolved.add(target)
    return resolved


def graph() -> dict[str, set[str]]:
    modules = source_modules()
    known = set(modules)
    return {name: imports_of(name, path, known) for name, path in modules.items()}


def layer_of(module: str) -> tuple[int, str] | None:
    for part, whole in PART_OF.items():
        if module == part or module.startswith(part + "."):
            module = whole
    for index, layer in enumerate(LAYERS):
        for prefix in layer:
            if module == prefix or module.startswith(prefix + "."):
                return index, prefix
    return None


def violations(edges: dict[str, set[str]]) -> list[str]:
    out = []
    for source, targets in sorted(edges.items()):
        if source == API:
            continue
        src = layer_of(source)
        for target in sorted(targets):
            if target == API:
                out.append(f"{source} -> {target}: the package API is the top; nothing below imports it")
                continue
            dst = layer_of(target)
            if src is None or dst is None:
                out.append(f"{source} -> {target}: a module in no layer (add its package to LAYERS)")
            elif src[1] == dst[1]:
                continue
            elif dst[0] < src[0]:
                out.append(f"{source} -> {target}: imports upward ({src[1]} is below {dst[1]})")
            elif dst[0] == src[0]:
                out.append(f"{source} -> {target}: {src[1]} and {dst[1]} are independent packages of one layer")
    return out


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_every_import_follows_the_layers():
    assert violations(graph()) == []


def test_no_import_cycles_lazy_imports_included():
    assert cycles(graph()) == []


def test_every_module_is_in_a_layer():
    missing = sorted(m for m in source_modules() if m != API and layer_of(m) is None)
    assert missing == []


@pytest.mark.parametrize("source, target, problem", [
    ("ddmr_cli.report.build", "ddmr_cli.cli.main", "imports upward"),
    ("ddmr_cli.storage.io", "ddmr_cli.config", "imports upward"),
    ("ddmr_cli.job", "ddmr_cli.bench.cost", "independent packages"),
    ("ddmr_cli.engine.stepper", "ddmr_cli", "the package API is the top"),
])
def test_the_contract_refuses_a_wrong_import(source, target, problem):
    edges = graph()
    edges[source] = {*edges[source], target}
    found = violations(edges)
    assert any(line.startswith(f"{source} -> {target}:") and problem in line for line in found), found


def test_the_cycle_check_sees_a_lazy_import(tmp_path):
    edges = graph()
    edges["ddmr_cli.storage.io"] = {*edges["ddmr_cli.storage.io"], "ddmr_cli.storage.jobdir"}
    assert ["ddmr_cli.storage.io", "ddmr_cli.storage.jobdir"] in cycles(edges)


def test_imports_inside_functions_are_read(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("def f():\n    from ddmr_cli.cli import main\n    import_module('ddmr_cli.report.build')\n")
    found = imports_of("ddmr_cli.storage.m", module, {"ddmr_cli.cli.main", "ddmr_cli.report.build", "ddmr_cli.cli"})
    assert found == {"ddmr_cli.cli.main", "ddmr_cli.report.build"}


def readme_layout() -> dict[str, str]:
    """The README's Layout section: each listed path (``ddmr_cli/`` entries relative to the package)."""
    text = ROOT.joinpath("README.md").read_text(encoding="utf-8")
    block = text.split("## Layout", 1)[1].split("```", 2)[1]
    entries, inside = {}, False
    for line in block.splitlines():
        if not line.strip() or line.startswith(" " * 6):
            continue
        name = line.split()[0]
        if line.startswith("ddmr_cli/"):
            inside = True
            continue
        if not line.startswith(" "):
            inside = False
            entries[name] = line
        elif inside:
            entries["ddmr_cli/" + name] = line
    return entries


def test_the_readme_layout_lists_exactly_the_packages_and_modules_that_exist():
    listed = set(readme_layout())
    package = ROOT / "ddmr_cli"
    existing = {f"ddmr_cli/{p.name}/" for p in package.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    existing |= {f"ddmr_cli/{p.name}" for p in package.glob("*.py") if p.name != "__init__.py"}
    assert sorted(existing - listed) == [], "in the package, missing from the README's Layout"
    assert sorted(e for e in listed if e.startswith("ddmr_cli/") and e not in existing) == [], \
        "in the README's Layout, not in the package"
    for top in (e for e in listed if not e.startswith("ddmr_cli/")):
        assert (ROOT / top).exists(), f"{top} is in the README's Layout but not in the repository"
