"""The compiled Ogden point kernel (``ogden_kernel.c``), built with cffi at first use.

Same formulas and the same outputs as :func:`fem_sim.material.ogden.ogden_point_kernel` (the numpy
reference, which the tests compare it with), several times faster: one pass per point instead
of ~40 batched numpy operations, a 3x3 Jacobi eigen-solver instead of LAPACK's per-matrix
calls (``bench/bench_kernel.py``).

The extension is built and cached by :mod:`fem_sim.cext`; if no C compiler is available,
:func:`load` returns None and callers use the numpy kernel (with a warning).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fem_sim import cext

SOURCE = Path(__file__).with_name("ogden_kernel.c")
CDEF = """
int ogden_points(int n, const double *F_all, int nterms, const double *ck, const double *mk,
                 double K, int vol_log, int want_tangent, double *W_all, double *P_all,
                 double *A_all, double *J_all);
int ogden_threads(int n);
"""
# No -ffast-math: the kernel relies on NaN and isfinite. OpenMP over the points. -O3 gives the
# same bits as -O2 (ISO C: no FMA contraction, no reassociation) and a faster pass with
# tangents (bench/bench_kernel.py); no -march=native, so the built module runs on any x86-64.
COMPILE_ARGS = ["-O3", "-std=c99", "-fopenmp"]


def load():
    """The compiled module (with ``.ffi`` and ``.lib``), or None if it cannot be built."""
    return cext.load("ogden", SOURCE, CDEF, "using the numpy kernel (several times slower)",
                     extra_compile_args=COMPILE_ARGS, extra_link_args=["-fopenmp"],
                     libraries=["m"])


def threads(n: int = 0) -> int:
    """Threads of the compiled kernel: ``n > 0`` sets the count; returns the count in force
    (1 without the compiled kernel).
    """
    mod = load()
    return 1 if mod is None else int(mod.lib.ogden_threads(int(n)))


def _ptr(ffi, arr: np.ndarray):
    return ffi.cast("double *", arr.ctypes.data)


def ogden_points(F: np.ndarray, c, m, K: float, volumetric: str, tangent: bool,
                 out: tuple | None = None):
    """Compiled kernel; arguments and results as :func:`fem_sim.material.ogden.ogden_point_kernel`.

    ``out`` = (W (n,), P (n, 9), A (n, 81) or None, J (n,)): C-contiguous float64 arrays to
    write into (for example views of quadrature-function arrays), instead of new ones.
    """
    mod = load()
    if mod is None:
        raise RuntimeError("compiled Ogden kernel unavailable")
    ffi, lib = mod.ffi, mod.lib
    F = np.ascontiguousarray(F, dtype=np.float64).reshape(-1, 9)
    n = F.shape[0]
    if out is None:
        out = (np.empty(n), np.empty((n, 9)), np.empty((n, 81)) if tangent else None,
               np.empty(n))
    W, P, A, J = out
    for arr in (W, P, J) + ((A,) if tangent else ()):
        if not (arr.flags.c_contiguous and arr.dtype == np.float64 and arr.shape[0] == n):
            raise ValueError("ogden_points: output arrays must be C-contiguous float64 with "
                             f"{n} rows")
    ck = np.ascontiguousarray(c, dtype=np.float64)
    mk = np.ascontiguousarray(m, dtype=np.float64)
    lib.ogden_points(n, _ptr(ffi, F), ck.size, _ptr(ffi, ck), _ptr(ffi, mk), float(K),
                     int(volumetric == "log"), int(bool(tangent)), _ptr(ffi, W), _ptr(ffi, P),
                     _ptr(ffi, A) if tangent else ffi.NULL, _ptr(ffi, J))
    return W, P, A, J
