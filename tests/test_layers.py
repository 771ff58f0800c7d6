"""Each folder is one floor, and floors point one way (docs/ARCHITECTURE.md, "Floors").

A folder is a direct sub-package of ``addedinertia_env`` (``addedinertia_env.sim``, with
everything below it: ``sim/effects/`` is part of ``sim``) or one of the other top-level
packages (``agents``, ``hw_adapter``). :data:`FLOORS` gives each folder its floor; a module
imports only folders on its own floor or lower ones, every import counted (a function-local
one, one under ``TYPE_CHECKING``), with no exception for any file. Folders on one floor may
use each other, but no folders import each other round a loop, and no modules either.

The tests at the end hold docs/ARCHITECTURE.md to this table: the folders its tree names
exist, every floor folder is in its floors table on the same floor, and the files it names
in a folder are there."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = "addedinertia_env"
PACKAGES = (PKG, "agents", "hw_adapter")
DOC = ROOT / "docs" / "ARCHITECTURE.md"

# The floors, lowest first. Keep docs/ARCHITECTURE.md's table in step with this one.
FLOORS: dict[str, int] = {
    # 0 foundation: files, the machine line, configuration, strict JSON; and the package root,
    #   whose __init__ only registers the Gymnasium ids (by name: it imports nothing of the project)
    PKG: 0, f"{PKG}.foundation": 0,
    # 1 the rig contract: the Rig protocol, KnownRig, MotorCommand and Reading
    f"{PKG}.rig": 1,
    # 2 on the contract alone: the loops to the drive, hydrodynamics, run records
    f"{PKG}.loop": 2, f"{PKG}.hydro": 2, f"{PKG}.records": 2,
    # 3 the simulator: model, laws, effects, engines, presets
    f"{PKG}.sim": 3,
    # 4 the experiment: protocol, runner, task, metrics, scenarios
    f"{PKG}.experiment": 4,
    # 5 estimators, diagnosis and controllers
    f"{PKG}.identify": 5, f"{PKG}.discover": 5, f"{PKG}.decay": 5, "agents": 5,
    # 5 how an episode is scored (the one scoring function), beside the estimators it calls
    f"{PKG}.evaluation": 5,
    # 6 applications: simulation runs, environments, training, the benchmark, the bench hardware
    f"{PKG}.apps": 6, f"{PKG}.envs": 6, f"{PKG}.vector": 6, f"{PKG}.learning": 6, f"{PKG}.bench": 6,
    "hw_adapter": 6,
    # 7 report generators (docs/*.md, the perf page too)
    f"{PKG}.reports": 7,
    # 8 the command line: every subcommand, on top of everything
    f"{PKG}.cli": 8,
}
NAMES = {0: "foundation", 1: "rig contract", 2: "loops, hydrodynamics, records", 3: "simulator", 4: "experiment",
         5: "estimators/controllers", 6: "applications", 7: "reports", 8: "cli"}


def folder_of(module: str) -> str:
    """The floor folder of a dotted module: ``addedinertia_env.sim.effects.x`` -> ``addedinertia_env.sim``."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == PKG and len(parts) > 1 else parts[0]


def module_name(path: Path, root: Path = ROOT) -> str:
    """The dotted module of a file under ``root``."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules(root: Path = ROOT) -> list[Path]:
    """Every Python file of the packages."""
    return [p for pkg in PACKAGES for p in sorted((root / pkg).rglob("*.py"))]


def imports(root: Path = ROOT) -> list[tuple[str, str, int]]:
    """(importing module, imported module, line) for every import of a project module, anywhere in a file."""
    out = []
    for path in modules(root):
        mod = module_name(path, root)
        base = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    up = base[: len(base) - (node.level - 1)]
                    stem = ".".join(up + ([node.module] if node.module else []))
                    targets = [f"{stem}.{a.name}" if not node.module else stem for a in node.names]
                else:  # ``from addedinertia_env import sim``: the module imported is addedinertia_env.sim
                    targets = [f"{node.module}.{a.name}" if _is_module(f"{node.module}.{a.name}", root)
                               else node.module for a in node.names]
            else:
                continue
            out += [(mod, t, node.lineno) for t in targets if t.split(".")[0] in PACKAGES]
    return out


def _is_module(name: str, root: Path = ROOT) -> bool:
    path = root / name.replace(".", "/")
    return path.with_suffix(".py").exists() or (path / "__init__.py").exists()


def _existing_module(name: str, root: Path = ROOT) -> str:
    """``name`` or its longest prefix that is a module file (``from m import f`` names ``m.f``)."""
    while name and not _is_module(name, root):
        name = name.rpartition(".")[0]
    return name


def folder_graph(edges: list[tuple[str, str, int]]) -> dict[str, set[str]]:
    """Folder -> the other folders its modules import."""
    graph: dict[str, set[str]] = {}
    for src, dst, _ in edges:
        a, b = folder_of(src), folder_of(dst)
        if a != b:
            graph.setdefault(a, set()).add(b)
    return graph


def module_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module -> the project modules it imports (anywhere in the file)."""
    graph: dict[str, set[str]] = {}
    for src, dst, _ in imports(root):
        dst = _existing_module(dst, root)
        if dst and dst != src:
            graph.setdefault(src, set()).add(dst)
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected sets of nodes (more than one) in ``graph`` (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
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


def floor_folders(root: Path = ROOT) -> set[str]:
    """The folders there are: the packages under addedinertia_env/ and the other top-level packages."""
    found = {f"{PKG}.{p.parent.name}" for p in (root / PKG).glob("*/__init__.py")}
    return found | {PKG} | {pkg for pkg in PACKAGES if pkg != PKG}


def upward_imports(edges: list[tuple[str, str, int]], floors: dict[str, int]) -> list[str]:
    """Each import of a folder on a higher floor, as ``src:line (floor) imports dst (floor)``."""
    bad = []
    for src, dst, line in edges:
        fs, fd = floors.get(folder_of(src)), floors.get(folder_of(dst))
        if fs is not None and fd is not None and fd > fs:
            bad.append(f"{src}:{line} ({NAMES.get(fs, fs)}) imports {dst} ({NAMES.get(fd, fd)})")
    return bad


# ---------------------------------------------------------------------------------- the code


def test_every_folder_is_a_floor_and_every_floor_a_folder():
    there = floor_folders()
    assert not there - set(FLOORS), f"folders without a floor in tests/test_layers.py FLOORS: {sorted(there - set(FLOORS))}"
    assert not set(FLOORS) - there, f"FLOORS names folders that are not there: {sorted(set(FLOORS) - there)}"


def test_the_package_root_holds_no_loose_module():
    """addedinertia_env/ holds folders and its __init__ (the Gymnasium registration), nothing else."""
    loose = sorted(p.name for p in (ROOT / PKG).glob("*.py") if p.name != "__init__.py")
    assert not loose, f"modules loose in {PKG}/ (put each in the folder of its floor): {loose}"


def test_the_package_root_imports_nothing_of_the_project():
    """``import addedinertia_env`` registers the ids by name (entry points as strings), so it stays floor 0."""
    tree = ast.parse((ROOT / PKG / "__init__.py").read_text())
    names = [n.module if isinstance(n, ast.ImportFrom) else a.name for n in ast.walk(tree)
             if isinstance(n, (ast.Import, ast.ImportFrom)) for a in getattr(n, "names", [])]
    assert not [n for n in names if n and n.split(".")[0] in PACKAGES]
    import gymnasium as gym

    import addedinertia_env  # noqa: F401

    assert "AddedInertia/ReverseStroke-v0" in gym.registry


def test_no_folder_imports_a_higher_floor():
    bad = upward_imports(imports(), FLOORS)
    assert not bad, "imports against the floors:\n" + "\n".join(bad)


def test_no_folder_cycle():
    """No two folders import each other, directly or round a loop (floor-mates included)."""
    cycles = [sorted(c) for c in import_cycles(folder_graph(imports()))]
    assert not cycles, f"folder import cycles: {cycles}"


def test_no_module_cycle():
    """No two modules import each other, directly or round a loop, even lazily (style.md)."""
    cycles = [sorted(c) for c in import_cycles(module_graph())]
    assert not cycles, f"import cycles (move the shared piece into a lower module): {cycles}"


def test_nothing_but_the_cli_imports_it():
    bad = [f"{s}:{n} imports {d}" for s, d, n in imports()
           if folder_of(d) == f"{PKG}.cli" and folder_of(s) != f"{PKG}.cli"]
    assert not bad, bad


def test_no_private_name_is_imported_across_folders():
    bad = []
    for path in modules():
        mod = module_name(path)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                if folder_of(node.module) != folder_of(mod) and node.module.split(".")[0] in PACKAGES:
                    bad += [f"{mod}: {node.module}.{a.name}" for a in node.names
                            if a.name.startswith("_") and not a.name.endswith("__")]
    assert not bad, bad


# ------------------------------------------------------------------- the checks can fail


def test_a_new_upward_import_is_caught(tmp_path):
    """A simulator module that imported the task, or a loose root module, would be reported."""
    pkg = tmp_path / PKG
    for sub in ("sim", "experiment"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text('"""x"""\n')
    (pkg / "__init__.py").write_text('"""x"""\n')
    (pkg / "experiment" / "task.py").write_text("X = 1\n")
    (pkg / "sim" / "forces.py").write_text("def f():\n    from addedinertia_env.experiment.task import X\n    return X\n")
    edges = imports(tmp_path)
    assert edges == [(f"{PKG}.sim.forces", f"{PKG}.experiment.task", 2)]
    assert upward_imports(edges, FLOORS) == [
        f"{PKG}.sim.forces:2 (simulator) imports {PKG}.experiment.task (experiment)"]
    assert folder_of(f"{PKG}.sim.effects.registry") == f"{PKG}.sim"
    assert floor_folders(tmp_path) >= {f"{PKG}.sim", f"{PKG}.experiment"}


def test_an_import_cycle_is_caught():
    """The cycle check can fail: a loop of three, beside a chain that is no loop; folders alike."""
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert import_cycles(graph) == [{"a", "b", "c"}]
    assert import_cycles({"a": {"b"}, "b": {"c"}}) == []
    edges = [(f"{PKG}.identify.x", f"{PKG}.discover.y", 1), (f"{PKG}.discover.z", f"{PKG}.identify.common", 3)]
    assert import_cycles(folder_graph(edges)) == [{f"{PKG}.identify", f"{PKG}.discover"}]


# ------------------------------------------------------------- docs/ARCHITECTURE.md's claims


def doc_tree(text: str | None = None) -> dict[str, list[str]]:
    """The folders of ARCHITECTURE.md's tree block (``addedinertia_env.sim``, ``agents``) -> the files it names there."""
    text = DOC.read_text() if text is None else text
    block = text.split("## The tree", 1)[1].split("```", 2)[1]
    tree: dict[str, list[str]] = {}
    current = None
    for line in block.splitlines():
        top = re.match(r"^(\w+)/", line)
        sub = re.match(r"^  (\w+)/", line)
        if top:
            current = top.group(1) if top.group(1) in PACKAGES else None
            if current == PKG:
                current = None  # the package root's own line
        elif sub:
            current = f"{PKG}.{sub.group(1)}"
        if current is not None:
            tree.setdefault(current, [])
            tree[current] += re.findall(r"(?<![\w/.])(\w+(?:/\w+)*\.py)\b", line)
    return tree


def doc_floors(text: str | None = None) -> dict[str, int]:
    """The floors table of ARCHITECTURE.md: folder (dotted) -> floor."""
    out: dict[str, int] = {}
    for row in re.findall(r"^\| *(\d) *\|([^|]*)\|", DOC.read_text() if text is None else text, re.M):
        for name in re.findall(r"`([\w/]+)/`", row[1]):
            out[name.replace("/", ".") if name in PACKAGES or name.startswith(PKG) else f"{PKG}.{name}"] = int(row[0])
    return out


def test_the_architecture_tree_names_every_folder_there_is_and_no_other():
    named = set(doc_tree())
    assert named, "docs/ARCHITECTURE.md: no tree block found under '## The tree'"
    there = floor_folders() - {PKG}
    assert not named - there, f"ARCHITECTURE.md names folders that are not there: {sorted(named - there)}"
    assert not there - named, f"folders that ARCHITECTURE.md's tree does not name: {sorted(there - named)}"


def test_the_files_the_architecture_names_are_there():
    missing = []
    for folder, files in doc_tree().items():
        where = ROOT / folder.replace(".", "/")
        for name in files:
            if not (where / name).exists() and not list(where.rglob(Path(name).name)):
                missing.append(f"{folder.replace('.', '/')}/{name}")
    assert not missing, f"files ARCHITECTURE.md's tree names that are not there: {missing}"


def test_the_architecture_floors_table_is_this_one():
    assert doc_floors() == FLOORS, "ARCHITECTURE.md's floors table and tests/test_layers.py FLOORS differ"


def test_the_architecture_checks_can_fail():
    """A page whose tree names a folder that is gone, or puts a folder on another floor, is read as such."""
    page = ("## The tree\n\n```\naddedinertia_env/   root\n  sim/        forces.py, gone.py\n  attic/      old\n"
            "agents/     x.py\n```\n\n| floor | folders | what |\n|---|---|---|\n| 3 | `sim/` | simulator |\n"
            "| 2 | `experiment/` `agents/` | wrong floors |\n")
    tree = doc_tree(page)
    assert set(tree) == {f"{PKG}.sim", f"{PKG}.attic", "agents"} and tree[f"{PKG}.sim"] == ["forces.py", "gone.py"]
    assert doc_floors(page) == {f"{PKG}.sim": 3, f"{PKG}.experiment": 2, "agents": 2} != FLOORS


def test_the_water_is_defined_once():
    """ARCHITECTURE.md: hydrodynamics in one place, the water's density and gravity in hydro/water.py only."""
    where = []
    for path in modules():
        for node in ast.walk(ast.parse(path.read_text())):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
                node, ast.AnnAssign) else []
            where += [f"{module_name(path)}.{t.id}" for t in targets
                      if isinstance(t, ast.Name) and re.fullmatch(r"RHO(_WATER)?|GRAVITY|G_ACCEL", t.id)]
    assert sorted(where) == [f"{PKG}.hydro.water.GRAVITY", f"{PKG}.hydro.water.RHO_WATER"], where
