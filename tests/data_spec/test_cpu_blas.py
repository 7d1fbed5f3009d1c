"""OpenBLAS' kernels chosen from the CPU's instruction sets (data_spec/cpu_blas.py)."""

import os
import re
import subprocess
import sys

from data_spec import cpu_blas

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


def test_this_environment_loads_the_chosen_kernels():
    """A fresh interpreter of this environment (its .pth runs configure() at start-up) makes
    OpenBLAS report the kernel set chosen from /proc/cpuinfo. If numpy's BLAS is not an
    OpenBLAS that picks kernels at run time, it reports none and there is nothing to check."""
    want = cpu_blas.coretype(cpu_blas.cpu_flags())
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    env["OPENBLAS_VERBOSE"] = "2"
    out = subprocess.run([sys.executable, "-c", "import numpy"], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    cores = re.findall(r"^Core: (\S+)", out.stderr + out.stdout, flags=re.M)
    if want and cores:
        assert cores == [want], (cores, want)
