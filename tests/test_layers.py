"""Layers point one way: a module imports only modules of its own or a lower layer
(docs/ARCHITECTURE.md, "Layers"). Every import counts, also one inside a function.

The table maps a module (the longest matching dotted prefix) to its layer. A new
upward import fails here; so does an import cycle between layers."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("addedinertia_env", "agents", "hw_adapter")

# Lowest first. Keep docs/ARCHITECTURE.md's table in step with this one.
LAYERS: dict[str, int] = {
    # 0 foundation: files, machine, configuration, JSON
    "addedinertia_env": 0, "addedinertia_env.foundation.atomic": 0, "addedinertia_env.foundation.machine": 0,
    "addedinertia_env.foundation.config_io": 0, "addedinertia_env.foundation.jsonable": 0,
    # 1 physics: the simulated truth, the rig protocol, presets, hull geometry
    "addedinertia_env.sim": 1, "addedinertia_env.hydro": 1,
    # 2 data: run records and what reads them without a model
    "addedinertia_env.records.record": 2, "addedinertia_env.records.run_record": 2, "addedinertia_env.records.plausibility": 2, "addedinertia_env.records.daq": 2,
    "addedinertia_env.records.record_error": 2,
    "addedinertia_env.records.consistency": 2,
    "addedinertia_env.records.plots": 2,
    # 3 the experiment and the task (observation, reward, controller context, metrics, scenarios)
    "addedinertia_env.experiment": 3, "addedinertia_env.experiment.task": 3, "addedinertia_env.experiment.metrics": 3,
    "addedinertia_env.experiment.scenarios": 3,
    # 4 estimators, diagnosis and controllers
    "addedinertia_env.identify": 4, "addedinertia_env.discover": 4, "addedinertia_env.decay": 4, "agents": 4,
    # 5 applications: simulation runs, environments, training, benchmark, bench hardware
    "addedinertia_env.apps.simulate": 5, "addedinertia_env.apps.discovery_dataset": 5, "addedinertia_env.envs": 5, "addedinertia_env.vector": 5,
    "addedinertia_env.learning": 5, "addedinertia_env.bench": 5, "addedinertia_env.apps.sweeps": 5, "addedinertia_env.evaluation.scoring": 5,
    "addedinertia_env.reports.perf": 5, "addedinertia_env.apps.energy_budget": 5, "hw_adapter": 5,
    # 6 the command line
    "addedinertia_env.cli": 6,
    # 7 report generators (docs/*.md): may use the CLI's public helpers
    "addedinertia_env.reports": 7,
}
NAMES = {0: "foundation", 1: "physics", 2: "data", 3: "experiment/task", 4: "estimators/controllers",
         5: "applications", 6: "cli", 7: "reports"}

# Known upward imports, each with its reason; the list may only shrink.
ALLOWED: dict[tuple[str, str], str] = {}



def layer_of(module: str) -> int | None:
    parts = module.split(".")
    for k in range(len(parts), 0, -1):
        prefix = ".".join(parts[:k])
        if prefix in LAYERS:
            return LAYERS[prefix]
    return None


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports() -> list[tuple[str, str, int]]:
    """(importing module, imported module, line) for every import of a project module."""
    out = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            mod = module_name(path)
            base = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    targets = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom):
                    if node.level:
                        up = base[: len(base) - (node.level - 1)]
                        stem = ".".join(up + ([node.module] if node.module else []))
                        # ``from . import x``: x may be a module
                        targets = [f"{stem}.{a.name}" if not node.module else stem for a in node.names]
                    else:
                        targets = [node.module or ""]
                else:
                    continue
                out += [(mod, t, node.lineno) for t in targets if t.split(".")[0] in PACKAGES]
    return out


def test_every_module_has_a_layer():
    missing = sorted({m for m, _, _ in imports() if layer_of(m) is None})
    assert not missing, f"modules without a layer in tests/test_layers.py LAYERS: {missing}"


def test_no_module_imports_a_higher_layer():
    bad = []
    for src, dst, line in imports():
        ls, ld = layer_of(src), layer_of(dst)
        if ld is not None and ls is not None and ld > ls and (src, dst) not in ALLOWED:
            bad.append(f"{src}:{line} ({NAMES[ls]}) imports {dst} ({NAMES[ld]})")
    assert not bad, "imports against the layers:\n" + "\n".join(bad)


def test_nothing_below_the_cli_imports_it():
    bad = [f"{s}:{n} imports {d}" for s, d, n in imports()
           if d.startswith("addedinertia_env.cli") and layer_of(s) < LAYERS["addedinertia_env.cli"]]
    assert not bad, bad


def test_no_private_name_is_imported_across_packages():
    bad = []
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            mod = module_name(path)
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                    top = node.module.split(".")[:2]
                    if top != mod.split(".")[:2]:
                        bad += [f"{mod}: {node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
    assert not bad, bad


def _existing_module(name: str) -> str:
    """``name`` or its longest prefix that is a module file (``from m import f`` names ``m.f``)."""
    while name:
        path = ROOT / name.replace(".", "/")
        if path.with_suffix(".py").exists() or (path / "__init__.py").exists():
            return name
        name = name.rpartition(".")[0]
    return name


def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (anywhere in the file)."""
    graph: dict[str, set[str]] = {}
    for src, dst, _ in imports():
        dst = _existing_module(dst)
        if dst and dst != src:
            graph.setdefault(src, set()).add(dst)
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected sets of modules (more than one) in ``graph`` (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle():
    """No two modules import each other, directly or round a loop, even lazily (style.md)."""
    cycles = [sorted(c) for c in import_cycles(import_graph())]
    assert not cycles, f"import cycles (move the shared piece into a lower module): {cycles}"


def test_a_new_upward_import_is_caught(tmp_path):
    """The check can fail: a rig module that imported the task would be reported."""
    assert layer_of("addedinertia_env.sim.forces") < layer_of("addedinertia_env.experiment.task")
    assert layer_of("addedinertia_env.apps.discovery_dataset") == LAYERS["addedinertia_env.apps.simulate"]
    assert layer_of("agents.base") < layer_of("addedinertia_env.bench.tuning")


def test_an_import_cycle_is_caught():
    """The cycle check can fail: a loop of three, beside a chain that is no loop."""
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert import_cycles(graph) == [{"a", "b", "c"}]
    assert import_cycles({"a": {"b"}, "b": {"c"}}) == []
