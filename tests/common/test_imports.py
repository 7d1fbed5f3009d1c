"""No import circle in the project's packages, counting imports inside functions too (an import
moved into a function hides a circle from Python, not from the design)."""

import ast
from pathlib import Path

ROOT = Path(__file__).parents[2]
PACKAGES = ("data_spec", "fem_sim", "surrogate", "liverviz", "liverreg")


def module_names(root: Path, packages=PACKAGES) -> dict[str, Path]:
    out = {}
    for pkg in packages:
        for f in (root / pkg).rglob("*.py"):
            parts = list(f.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f
    return out


def import_graph(root: Path, packages=PACKAGES) -> dict[str, set[str]]:
    """module -> the project modules it imports anywhere in its text (explicit imports only:
    importing a.b.c also runs a/__init__.py, but that is not an edge of the design)."""
    mods = module_names(root, packages)
    graph = {m: set() for m in mods}
    for m, f in mods.items():
        is_pkg = f.name == "__init__.py"
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    pkg = m.split(".") if is_pkg else m.split(".")[:-1]
                    pkg = pkg[: len(pkg) - node.level + 1]
                    base = ".".join(pkg + ([base] if base else []))
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.append(sub if sub in mods else base)
            for t in targets:
                while t and t not in mods:  # "import a.b.c" of a module, or a name in it
                    t = t.rpartition(".")[0]
                if t and t != m:
                    graph[m].add(t)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_checker_finds_a_circle_hidden_in_a_function(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pkg.b import g\n")
    (pkg / "b.py").write_text("def g():\n    from pkg import a\n")
    (pkg / "c.py").write_text("from . import a\n")
    graph = import_graph(tmp_path, ("pkg",))
    assert graph["pkg.c"] == {"pkg.a"}
    assert cycles(graph) == [["pkg.a", "pkg.b"]]


def test_no_import_circle_in_the_project():
    graph = import_graph(ROOT)
    assert len(graph) > 50
    assert cycles(graph) == []


def imported_roots(package: str) -> set[str]:
    """Top-level names a package imports (inside functions too), less the standard library
    and itself."""
    import sys

    roots = set()
    for f in (ROOT / package).rglob("*.py"):
        for node in ast.walk(ast.parse(f.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and not node.level
                     else [])
            roots |= {n.split(".")[0] for n in names if n}
    return roots - set(sys.stdlib_module_names) - {package}


def test_data_spec_needs_numpy_and_h5py_only():
    assert imported_roots("data_spec") <= {"numpy", "h5py"}


def test_liverreg_needs_numpy_scipy_and_data_spec_only():
    """The registration both environments share: no dolfinx, no gmsh, no JAX."""
    assert imported_roots("liverreg") <= {"numpy", "scipy", "data_spec"}


def test_the_trainer_never_imports_the_solver():
    assert not imported_roots("surrogate") & {"fem_sim", "dolfinx", "petsc4py", "mpi4py",
                                               "ufl", "ffcx", "gmsh"}
