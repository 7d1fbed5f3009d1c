"""The Makefile and the Dockerfiles install from the same package lists, the same way."""

import re
from pathlib import Path

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
