"""The Makefile and the Dockerfiles install from the same package lists, the same way."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]


def _packages(name):
    text = (ROOT / "requirements" / name).read_text()
    return [ln.split("#")[0].strip() for ln in text.splitlines() if ln.split("#")[0].strip()]


def test_solver_list_has_the_design_packages():
    pkgs = _packages("debian-packages.txt")
    for p in ("python3-dolfinx-real", "python3-petsc4py", "python3-mpi4py", "openmpi-bin",
              "python3-gmsh", "python3-meshio", "python3-h5py", "libopenblas0-pthread"):
        assert p in pkgs


def test_dockerfiles_and_makefile_read_the_same_lists():
    make = (ROOT / "Makefile").read_text()
    for image, lst, target in (("solver", "debian-packages.txt", "setup-solver"),
                               ("trainer", "debian-packages-trainer.txt", "setup-trainer")):
        docker = (ROOT / "docker" / f"{image}.Dockerfile").read_text()
        assert f"COPY requirements/{lst}" in docker
        assert f"scripts/setup_system.sh requirements/{lst}" in docker
        assert f"make {target}" in docker
        assert f"scripts/setup_system.sh requirements/{lst}" in make
        # no package list of its own: no apt-get install in the Dockerfile
        assert not re.search(r"apt-get\s+install", docker)


def test_solver_constraints_pin_numpy_1():
    text = (ROOT / "requirements" / "solver-constraints.txt").read_text()
    assert re.search(r"^numpy==1\.", text, re.M)


def test_trainer_lock_is_pinned():
    lines = _packages("trainer.lock")
    assert lines and all("==" in ln for ln in lines)
    names = {ln.split("==")[0].lower() for ln in lines}
    assert {"jax", "jaxlib", "flax", "optax", "h5py", "numpy", "matplotlib"} <= names
    numpy = next(ln for ln in lines if ln.lower().startswith("numpy=="))
    assert int(numpy.split("==")[1].split(".")[0]) >= 2


def _source_files():
    out = set()
    for pkg in ("data_spec", "fem_sim", "surrogate", "liverviz"):
        for f in (ROOT / pkg).rglob("*"):
            if f.suffix in (".py", ".c") and "__pycache__" not in f.parts:
                out.add(f.relative_to(ROOT).as_posix())
    out |= {f.relative_to(ROOT).as_posix() for f in (ROOT / "data_spec" / "scenes").glob("*.toml")}
    return out


@pytest.mark.slow
def test_wheel_holds_every_module_and_kernel_and_runs_in_a_fresh_environment(tmp_path):
    """Build a wheel from a copy of the sources (no network: Debian's setuptools and wheel),
    check it holds every module, C kernel and scene, install it into a fresh environment that
    sees only Debian's packages, and run the command lines from outside the repository."""
    import shutil
    import subprocess
    import zipfile

    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        ".git", ".venv*", "runs", "build", "*.egg-info", "__pycache__", ".pytest_cache",
        ".ruff_cache", "bench", "docs", "tests"))
    dist = tmp_path / "dist"
    # Debian's Python builds it: its setuptools and wheel are there in every environment the
    # tests run under (the trainer's virtualenv has no wheel package)
    out = subprocess.run(["/usr/bin/python3", "-m", "pip", "wheel", "-q", "--no-deps",
                          "--no-build-isolation", "-w", str(dist), str(src)],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    (wheel,) = dist.glob("liverfem-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = _source_files() - names
    assert not missing, sorted(missing)
    assert any(n.endswith("entry_points.txt") for n in names)

    venv = tmp_path / "venv"
    subprocess.run(["/usr/bin/python3", "-m", "venv", "--system-site-packages", str(venv)],
                   check=True, timeout=300)
    out = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "-q",
                          "--no-deps", str(wheel)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    for cmd in ([str(venv / "bin" / "python"), "-m", "fem_sim", "--help"],
                [str(venv / "bin" / "liverfem-sim"), "--help"],
                [str(venv / "bin" / "python"), "-m", "data_spec", "--help"]):
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
        assert out.returncode == 0, (cmd, out.stderr)
        assert "usage" in out.stdout.lower(), out.stdout
    where = subprocess.run([str(venv / "bin" / "python"), "-c",
                            "import fem_sim.solver.tet as t; print(t.SOURCE, t.SOURCE.exists())"],
                           capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert str(venv) in where.stdout and where.stdout.strip().endswith("True"), where
