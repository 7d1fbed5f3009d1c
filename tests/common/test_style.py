"""Rules of the house that a reviewer would otherwise check by hand: short functions, one home
for each job (nothing imports bench/, no file edits the import path), and the design registry
as the only place that knows a design's name."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).parents[2]
PACKAGES = ("data_spec", "fem_sim", "surrogate", "liverreg", "liverviz")
DESIGN_MODULES = {"designs.py", "nodewise.py", "basis.py", "population_basis.py", "config.py"}


def python_files(*tops: str):
    for top in tops:
        yield from sorted((ROOT / top).rglob("*.py"))


def long_functions(files, limit: int, names: set[str] | None = None) -> list[str]:
    out = []
    for f in files:
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and \
                    (names is None or node.name in names):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    out.append(f"{f.name}:{node.lineno} {node.name}: {n} lines")
    return out


def test_package_functions_fit_a_screen_and_bench_mains_are_short():
    assert long_functions(python_files(*PACKAGES), 60) == []
    assert long_functions(python_files("bench"), 80, {"main"}) == []


def test_the_long_function_check_finds_one(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("def f():\n" + "    x = 1\n" * 61)
    assert long_functions([f], 60) != [] and long_functions([f], 62) == []


def test_nothing_imports_bench_and_no_file_edits_the_import_path():
    bench = {p.stem for p in (ROOT / "bench").glob("*.py")}
    found = []
    for f in python_files(*PACKAGES, "tests", "scripts", "demos"):
        for node in ast.walk(ast.parse(f.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            found += [f"{f.relative_to(ROOT)} imports {n}" for n in names
                      if n.split(".")[0] in bench | {"bench"}]
    path_edit = "sys." + "path"
    for f in python_files(*PACKAGES, "tests", "scripts", "demos", "bench"):
        if path_edit in f.read_text():
            found.append(f"{f.relative_to(ROOT)} edits {path_edit}")
    assert found == []


DESIGN_TEST = re.compile(r"""(==|!=)\s*["'](nodewise|basis|population_basis)["']|"""
                         r"""\bin\s*\(\s*["'](nodewise|basis|population_basis)["']""")


def test_no_design_name_is_tested_outside_the_registry():
    """The predictor, the manipulator, the latency code and the studies ask a design's class
    (DESIGNS[name]) what it does; only the design modules and the configs spell names."""
    found = []
    for f in python_files("surrogate", "liverviz", "bench", "scripts"):
        if f.name in DESIGN_MODULES and f.parent.name == "surrogate":
            continue
        for i, line in enumerate(f.read_text().splitlines(), 1):
            if DESIGN_TEST.search(line):
                found.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()}")
    assert found == []
    assert DESIGN_TEST.search('if pred.design == "basis":')
    assert DESIGN_TEST.search('if pred.design in ("basis", "population_basis"):')
