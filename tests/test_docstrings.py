"""Every module, and every public function, class and method of the packages, says what it
does (style.md: "docstrings on public functions: what, units, returns").

Public: a module-level function or class, or a method of a public class, whose name has no
leading underscore, in a module whose own path has none (``_private.py`` modules are
skipped). Dunder methods are not public API (``__init__`` is covered by its class's
docstring). A property counts as a method. The check reads the source with :mod:`ast`;
it imports nothing.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("addedinertia_env", "agents", "hw_adapter")

# Names without a docstring on purpose, each with its reason; keep this list short.
ALLOWED: dict[str, str] = {}

# A docstring shorter than this says nothing ("Run.", "Helper.").
MIN_CHARS = 12


def _public(name: str) -> bool:
    return not name.startswith("_")


def _overload_or_override_only(node: ast.AST) -> bool:
    """``@typing.overload`` stubs and a property's setter or deleter (the getter's docstring is the
    property's) carry no docstring of their own."""
    for dec in getattr(node, "decorator_list", []):
        name = dec.attr if isinstance(dec, ast.Attribute) else getattr(dec, "id", "")
        if name in ("overload", "setter", "deleter"):
            return True
    return False


def public_definitions(tree: ast.Module, module: str):
    """(qualified name, node) of each public function, class and method of class bodies."""
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and _public(node.name):
            if not _overload_or_override_only(node):
                yield f"{module}.{node.name}", node
        elif isinstance(node, ast.ClassDef) and _public(node.name):
            yield f"{module}.{node.name}", node
            for item in node.body:
                if (isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and _public(item.name)
                        and not _overload_or_override_only(item)):
                    yield f"{module}.{node.name}.{item.name}", item


def _module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def missing_docstrings(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> list[str]:
    """``file:line name`` of every public definition with no (or a too short) docstring."""
    out = []
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            rel = path.relative_to(root)
            if any(p.startswith("_") and p != "__init__.py" for p in rel.parts):
                continue
            tree = ast.parse(path.read_text(), str(path))
            for name, node in public_definitions(tree, _module_name(path, root)):
                doc = ast.get_docstring(node) or ""
                if len(doc.strip()) < MIN_CHARS and name not in ALLOWED:
                    out.append(f"{rel}:{node.lineno} {name}")
    return out


def test_every_public_definition_has_a_docstring():
    missing = missing_docstrings()
    assert not missing, (f"{len(missing)} public definitions without a docstring (say what it does, the units "
                         "of physical arguments and of what it returns):\n" + "\n".join(missing))


def test_every_module_says_what_it_holds():
    """Every module (package ``__init__`` files too) opens with a docstring: what is in it, and
    for a package which file holds what."""
    missing = [str(path.relative_to(ROOT)) for pkg in PACKAGES for path in sorted((ROOT / pkg).rglob("*.py"))
               if len((ast.get_docstring(ast.parse(path.read_text())) or "").strip()) < MIN_CHARS]
    assert not missing, f"modules without a docstring: {missing}"


def test_the_allow_list_names_only_existing_undocumented_definitions():
    """An entry that is documented now (or gone) must leave ALLOWED."""
    found = set()
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            for name, node in public_definitions(ast.parse(path.read_text()), _module_name(path)):
                if len((ast.get_docstring(node) or "").strip()) < MIN_CHARS:
                    found.add(name)
    stale = sorted(set(ALLOWED) - found)
    assert not stale, f"remove from ALLOWED (documented or gone): {stale}"


def test_a_missing_docstring_is_caught(tmp_path):
    """The check can fail: an undocumented function, class and method are each reported."""
    pkg = tmp_path / "toy"
    pkg.mkdir()
    (pkg / "m.py").write_text(
        '"""Toy."""\n'
        "def f(x):\n    return x\n"
        "def _hidden():\n    pass\n"
        "class C:\n    def method(self):\n        pass\n"
        "    def __init__(self):\n        pass\n"
        "    @property\n    def documented(self):\n        '''The documented value, m.'''\n"
        "    @documented.setter\n    def documented(self, value):\n        pass\n"
        "class _Private:\n    def method(self):\n        pass\n")
    found = [line.split(" ", 1)[1] for line in missing_docstrings(tmp_path, ("toy",))]
    assert found == ["toy.m.f", "toy.m.C", "toy.m.C.method"]
