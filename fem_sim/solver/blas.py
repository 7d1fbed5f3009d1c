"""OpenBLAS's thread count, set for a scope.

OpenBLAS threads the level-1 operations of long vectors (GMRES' dot products and norms), and its
idle threads then spin for a while before they sleep, on the cores that the OpenMP kernels
(tetrahedra, Ogden points) and PARDISO want next: a simulation is slower with OpenBLAS on all
cores inside the load-step loop than on one. So the load-step loop runs OpenBLAS on one thread
(:func:`threads`), and MUMPS' factorisations, whose dense fronts are level-3 BLAS, get the
process's own count back (:func:`outer`).

Without OpenBLAS (another BLAS, or none found) both are no-ops.
"""

from __future__ import annotations

import ctypes
from contextlib import contextmanager

_lib = None
_tried = False
_outer: list[int] = []  # the counts in force outside each active scope, outermost first


def _openblas():
    global _lib, _tried
    if not _tried:
        _tried = True
        for name in ("libblas.so.3", "libopenblas.so.0"):  # numpy's, then MUMPS'
            try:
                lib = ctypes.CDLL(name)
            except OSError:
                continue
            if hasattr(lib, "openblas_set_num_threads"):
                _lib = lib
                break
    return _lib


def count() -> int:
    """OpenBLAS' thread count in force (0 without OpenBLAS)."""
    lib = _openblas()
    return int(lib.openblas_get_num_threads()) if lib is not None else 0


@contextmanager
def threads(n: int):
    """OpenBLAS on ``n`` threads inside the block, the previous count restored after it."""
    lib = _openblas()
    if lib is None or n <= 0:
        yield
        return
    old = int(lib.openblas_get_num_threads())
    _outer.append(old)
    lib.openblas_set_num_threads(int(n))
    try:
        yield
    finally:
        lib.openblas_set_num_threads(old)
        _outer.pop()


@contextmanager
def outer():
    """Inside a :func:`threads` scope: OpenBLAS on the count in force outside the outermost
    scope (the process's own), for a block that needs level-3 BLAS (a MUMPS factorisation).
    """
    with threads(_outer[0] if _outer else 0):
        yield
