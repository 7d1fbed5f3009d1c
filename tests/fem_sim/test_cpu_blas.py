"""OpenBLAS' kernels chosen from the CPU's instruction sets (fem_sim/cpu_blas.py)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from fem_sim import cpu_blas

ROOT = Path(__file__).parents[2]

SKYLAKE = {"sse2", "avx", "avx2", "fma", "avx512f", "avx512cd", "avx512bw", "avx512dq",
           "avx512vl"}


def test_widest_kernel_set_the_cpu_supports():
    assert cpu_blas.coretype(SKYLAKE) == "SkylakeX"
    assert cpu_blas.coretype(SKYLAKE - {"avx512vl"}) == "Haswell"  # AVX-512 subset missing
    assert cpu_blas.coretype({"avx", "avx2"}) == "Sandybridge"      # AVX2 without FMA
    assert cpu_blas.coretype({"sse2", "sse3"}) is None               # leave OpenBLAS' choice
    assert cpu_blas.coretype(set()) is None


def test_configure_keeps_a_users_choice_and_sets_otherwise(tmp_path):
    env = {"OPENBLAS_CORETYPE": "Zen"}
    assert cpu_blas.configure(env, SKYLAKE) == "Zen" and env["OPENBLAS_CORETYPE"] == "Zen"
    env = {}
    assert cpu_blas.configure(env, SKYLAKE) == "SkylakeX" and env == {
        "OPENBLAS_CORETYPE": "SkylakeX"}
    env = {}
    assert cpu_blas.configure(env, {"sse2"}) is None and env == {}
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nflags\t\t: fpu sse2 avx avx2 fma\n\nflags\t: avx512f\n")
    assert cpu_blas.cpu_flags(str(info)) == {"fpu", "sse2", "avx", "avx2", "fma"}  # first CPU
    assert cpu_blas.cpu_flags(str(tmp_path / "missing")) == set()


def test_importing_fem_sim_first_loads_the_chosen_kernels():
    """A fresh interpreter that imports fem_sim before numpy makes OpenBLAS load the kernel set
    chosen from /proc/cpuinfo (asked of the library itself: openblas_get_corename)."""
    want = cpu_blas.coretype(cpu_blas.cpu_flags())
    if want is None:
        pytest.skip("this CPU has none of the kernel sets fem_sim.cpu_blas chooses")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    code = ("import ctypes, fem_sim, numpy\n"
            "lib = ctypes.CDLL('libblas.so.3')\n"
            "f = getattr(lib, 'openblas_get_corename', None)\n"
            "if f is None: print('NOT-OPENBLAS')\n"
            "else: f.restype = ctypes.c_char_p; print(f().decode())\n")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    core = out.stdout.strip()
    if core == "NOT-OPENBLAS":
        pytest.skip("numpy's libblas.so.3 is not OpenBLAS here (nothing to choose)")
    assert core.lower() == want.lower(), (core, want)


def test_script_prints_the_choice():
    out = subprocess.run([sys.executable, str(ROOT / "fem_sim" / "cpu_blas.py")],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == (
        cpu_blas.coretype(cpu_blas.cpu_flags()) or "")
