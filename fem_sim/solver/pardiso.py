"""Serial sparse Cholesky in float32 (or float64) by MKL PARDISO (its own METIS ordering).

Why: on this project's Jacobians (symmetric positive definite at every stable state, constraints
lifted) a float32 supernodal Cholesky factorises faster than MUMPS' LDL^T, and PARDISO runs the
elimination tree and the dense fronts on all the cores it is given, where Debian's MUMPS is
built without OpenMP (only OpenBLAS' threads inside the fronts); ``bench/bench_jacobian.py``
measures both on the real liver's Jacobian.

MKL comes from PyPI's ``mkl`` wheel (installed into the solver environment by ``make setup``);
without it :func:`available` is False and the solver keeps MUMPS. PARDISO runs on MKL's GNU
threading layer, so it shares libgomp (and ``OMP_NUM_THREADS``) with the point kernels instead
of starting a second OpenMP runtime.

A matrix that is not positive definite (a tangent past a limit point, or far from
equilibrium) fails the Cholesky factorisation with :class:`~fem_sim.solver.ldlt.FactorError`;
the linear solver then factorises it with MUMPS' LDL^T (``fem_sim.solver.linear``).
"""

from __future__ import annotations

import ctypes
import functools
import os
import sys
from pathlib import Path

import numpy as np

from fem_sim.solver import ldlt
from fem_sim.solver.ldlt import FactorError

CDEF = """
void pardiso(void *pt, const int *maxfct, const int *mnum, const int *mtype, const int *phase,
             const int *n, const void *a, const int *ia, const int *ja, int *perm,
             const int *nrhs, int *iparm, const int *msglvl, void *b, void *x, int *error);
int MKL_Set_Threading_Layer(int code);
void MKL_Set_Num_Threads(int n);
int MKL_Get_Max_Threads(void);
"""
MKL_THREADING_GNU = 3
SPD = 2  # PARDISO's mtype: real symmetric positive definite
# PARDISO's error codes (phase 22: -4 is a zero or negative pivot: not positive definite)
ERRORS = {-1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
          -4: "zero or negative pivot (the matrix is not positive definite)",
          -5: "unclassified internal error", -7: "diagonal matrix is singular",
          -8: "32-bit integer overflow", -9: "not enough memory for out-of-core"}


def _candidates() -> list[Path]:
    """Where libmkl_rt may be: FEM_SIM_MKL, then this interpreter's environment (the ``mkl``
    wheel puts its libraries in ``<prefix>/lib``).
    """
    out = [Path(os.environ["FEM_SIM_MKL"])] if os.environ.get("FEM_SIM_MKL") else []
    for prefix in dict.fromkeys([sys.prefix, sys.base_prefix]):
        out += sorted(Path(prefix, "lib").glob("libmkl_rt.so*"), reverse=True)
    return out


@functools.lru_cache(maxsize=1)
def load():
    """(ffi, lib) of MKL's runtime library, or None when it is not installed (or
    ``FEM_SIM_MKL=off``).
    """
    if os.environ.get("FEM_SIM_MKL", "").lower() in ("off", "0", "no"):
        return None
    import cffi

    for path in _candidates():
        if not path.exists():
            continue
        try:
            # MKL's GNU threading layer calls libgomp, which must be global for it to find.
            ctypes.CDLL("libgomp.so.1", mode=ctypes.RTLD_GLOBAL)
            ffi = cffi.FFI()
            ffi.cdef(CDEF)
            lib = ffi.dlopen(str(path))
            lib.MKL_Set_Threading_Layer(MKL_THREADING_GNU)
            # An explicit count: on the GNU layer MKL otherwise follows libgomp's current
            # setting, which gmsh.initialize() sets to 1 (General.NumThreads), and a count
            # changed under factors made with more threads crashed PARDISO (seen with MKL
            # 2026.2 on this machine).
            lib.MKL_Set_Num_Threads(_default_threads())
            return ffi, lib
        except OSError:
            continue
    return None


def _default_threads() -> int:
    """OMP_NUM_THREADS when set, else the cores this process may run on."""
    try:
        return max(1, int(os.environ.get("OMP_NUM_THREADS", "").split(",")[0]))
    except ValueError:
        return max(1, len(os.sched_getaffinity(0)))


def available() -> bool:
    return load() is not None


def threads(n: int = 0) -> int:
    """PARDISO's threads: ``n > 0`` sets the count; returns the count in force (0 without
    MKL). The default: OMP_NUM_THREADS, else the cores the process may run on.
    """
    mod = load()
    if mod is None:
        return 0
    if n > 0:
        mod[1].MKL_Set_Num_Threads(int(n))
    return int(mod[1].MKL_Get_Max_Threads())


MAXFCT = 2  # numerical factorisations one analysis serves (PARDISO's maxfct)


class _Handle:
    """One PARDISO handle: the ordering and symbolic factorisation of one CSR pattern (phase
    11), shared by up to MAXFCT :class:`PardisoCholesky` instances, each with its own numerical
    factors (PARDISO's ``mnum``).
    """

    def __init__(self, ffi, lib, double: bool = False):
        self.ffi, self.lib, self.double = ffi, lib, double
        self.pt = np.zeros(64, dtype=np.int64)  # PARDISO's handle: 64 pointers
        self.iparm = np.zeros(64, dtype=np.int32)
        ip = self.iparm
        ip[0] = 1    # these settings, not PARDISO's defaults
        ip[7] = 0    # no iterative refinement (none is needed without perturbed pivots)
        ip[9] = 13   # pivot perturbation threshold (unused by Cholesky)
        ip[17] = -1  # report the factor's nonzeros
        ip[18] = -1  # and its Mflop
        ip[23] = 0   # classic parallel factorisation: faster than two-level at two threads
        ip[26] = 0   # no matrix checker (the arrays come from our assembly)
        ip[27] = 0 if double else 1   # 1: single precision, float32 values and factors
        ip[34] = 1   # zero-based ia / ja
        self.pattern = None
        self.users: set[int] = set()  # the mnum in use
        self.dummy = np.zeros(1, dtype=np.float64 if double else np.float32)

    def call(self, phase: int, mnum: int = 1, a: np.ndarray | None = None,
             b: np.ndarray | None = None, x: np.ndarray | None = None, nrhs: int = 1) -> int:
        ffi = self.ffi
        err = ffi.new("int *")
        i = lambda v: ffi.new("int *", v)  # noqa: E731
        ptr = lambda arr: ffi.cast("void *", arr.ctypes.data)  # noqa: E731
        d = self.dummy
        self.lib.pardiso(ptr(self.pt), i(MAXFCT), i(mnum), i(SPD), i(phase), i(self.n),
                         ptr(a if a is not None else d), ffi.cast("int *", self.ia.ctypes.data),
                         ffi.cast("int *", self.ja.ctypes.data),
                         ffi.cast("int *", self.perm.ctypes.data), i(nrhs),
                         ffi.cast("int *", self.iparm.ctypes.data), i(0),
                         ptr(b if b is not None else d), ptr(x if x is not None else d), err)
        return int(err[0])

    def same_pattern(self, indptr: np.ndarray, indices: np.ndarray) -> bool:
        return self.pattern is not None and np.array_equal(self.pattern[0], indptr) \
            and np.array_equal(self.pattern[1], indices)

    def analyse(self, indptr: np.ndarray, indices: np.ndarray) -> None:
        self.free()
        n = indptr.size - 1
        rows = np.repeat(np.arange(n, dtype=np.int32), np.diff(indptr))
        upper = indices >= rows
        if np.any((np.diff(indices) <= 0) & (np.diff(rows) == 0)):
            raise FactorError("PARDISO needs sorted, unique column indices in every CSR row")
        # PARDISO's own nested dissection (OpenMP METIS) on the scalar graph, returned in perm.
        # Measured on the real liver's easy case (two threads): back-solves 7.7 ms against
        # 13.5 ms with our METIS ordering of the 3x3-block graph as input (what MUMPS gets),
        # factorisations 0.19 s against 0.18 s.
        self.iparm[1] = 3
        self.iparm[4] = 2
        self.perm = np.zeros(n, dtype=np.int32)
        self.upper = np.flatnonzero(upper)
        self.n = n
        self.ia = np.zeros(n + 1, dtype=np.int32)
        np.cumsum(np.bincount(rows[upper], minlength=n), out=self.ia[1:])
        self.ja = np.ascontiguousarray(indices[upper], dtype=np.int32)
        self.pattern = (indptr.copy(), indices.copy())
        err = self.call(11)
        if err:
            self.pattern = None
            raise FactorError(f"PARDISO analysis failed: error {err} ({ERRORS.get(err, '?')})")

    def release(self, mnum: int) -> None:
        """Instance ``mnum`` is done: its factors go, and everything with the last user."""
        self.users.discard(mnum)
        if self.pattern is not None and self.pt.any():
            if self.users:
                self.call(0, mnum)  # this matrix's factors only
            else:
                self.free()

    def free(self) -> None:
        if self.pattern is not None and self.pt.any():
            self.call(-1)
            self.pt[:] = 0
        self.pattern = None


class PardisoCholesky:
    """Float32 Cholesky (LL^T) of a symmetric positive definite matrix given by its full CSR
    arrays, with the interface of :class:`~fem_sim.solver.ldlt.SerialLDLT`; float64 with
    ``double=True`` (twice the memory and about twice the time, for the many right-hand sides
    whose float32 refinement would cost more sweeps than that).

    ``factor(indptr, indices, values)`` analyses on the first call (and whenever the pattern
    changes: PARDISO's METIS nested dissection and symbolic factorisation),
    then factorises; ``solve(b)`` returns x (float64) with A x ~= b to float32
    accuracy (relative residual ~1e-3: GMRES refines it, :meth:`solve_refined`).
    """

    negative_pivots = 0  # a Cholesky factorisation that succeeded: the matrix is SPD

    def __init__(self, double: bool = False):
        mod = load()
        if mod is None:
            raise RuntimeError("MKL PARDISO is unavailable (pip install mkl)")
        self.ffi, self.lib = mod
        self.double = double
        self.dtype = np.float64 if double else np.float32
        self._h: _Handle | None = None
        self._join(_Handle(self.ffi, self.lib, double), 1)
        self.analyses = self.factorizations = 0
        ldlt._live.add(self)  # freed at exit with the MUMPS instances

    def share_ordering(self, other: PardisoCholesky) -> None:
        """Factorise with ``other``'s analysis (one handle, PARDISO's ``mnum``) while the
        pattern is the same: one ordering and symbolic factorisation serve both, each keeps
        its own factors. Measured on the real liver with P2 at 10 mm (71k unknowns): an
        analysis costs 0.5 s, and the solver's two slots (Newton's factorisations and the
        recurring small-strain one) each made their own. Nothing if ``other``'s handle is
        full.
        """
        h = other._h
        free = [m for m in range(1, MAXFCT + 1) if m not in h.users]
        if h is not self._h and free and h.double == self.double:
            self._join(h, free[0])

    def _join(self, h: _Handle, mnum: int) -> None:
        """Factorise as matrix ``mnum`` of handle ``h`` from now on; this instance's factors in
        its former handle are released (and that handle with its last user).
        """
        if self._h is not None:
            self._h.release(self._mnum)
        self._h, self._mnum = h, mnum
        h.users.add(mnum)
        self._factored = False

    @property
    def _perm(self) -> np.ndarray:
        return self._h.perm

    def free(self) -> None:
        """Release PARDISO's memory (also at garbage collection and at exit)."""
        h = getattr(self, "_h", None)
        if h is not None:
            h.release(self._mnum)
            self._h = None
        self._factored = False

    __del__ = free

    def factor(self, indptr: np.ndarray, indices: np.ndarray, values: np.ndarray) -> None:
        h = self._h
        if h is None:
            raise FactorError("PARDISO factorisation after free()")
        if not h.same_pattern(indptr, indices):
            if h.pattern is not None and h.users != {self._mnum}:
                # shared and analysed for another pattern: a handle of its own
                self._join(_Handle(self.ffi, self.lib, self.double), 1)
                h = self._h
            h.analyse(indptr, indices)
            self.analyses += 1
        self._a = np.ascontiguousarray(values[h.upper], dtype=self.dtype)
        self._factored = False
        err = h.call(22, self._mnum, self._a)
        if err:
            raise FactorError(f"PARDISO Cholesky failed: error {err} "
                              f"({ERRORS.get(err, '?')})")
        self.factorizations += 1
        self._factored = True

    def solve(self, b: np.ndarray) -> np.ndarray:
        """One back-solve with the factors (float64 result; ~1e-3 relative error)."""
        if not self._factored:
            raise FactorError("PARDISO solve without a factorisation")
        rhs = np.ascontiguousarray(b, dtype=self.dtype)
        x = np.empty_like(rhs)
        err = self._h.call(33, self._mnum, self._a, rhs, x)
        if err:
            raise FactorError(f"PARDISO solve failed: error {err} ({ERRORS.get(err, '?')})")
        return x.astype(np.float64, copy=False)

    def solve_block(self, b: np.ndarray) -> np.ndarray:
        """Back-solves of the rows of ``b`` (k, n) in one call (PARDISO's multiple right-hand
        sides, column-major: each row contiguous), float64 result.
        """
        if not self._factored:
            raise FactorError("PARDISO solve without a factorisation")
        rhs = np.ascontiguousarray(b, dtype=self.dtype)
        x = np.empty_like(rhs)
        err = self._h.call(33, self._mnum, self._a, rhs, x, nrhs=rhs.shape[0])
        if err:
            raise FactorError(f"PARDISO solve failed: error {err} ({ERRORS.get(err, '?')})")
        return x.astype(np.float64, copy=False)

    def solve_refined(self, A, b: np.ndarray, rtol: float, maxit: int = 30):
        """GMRES on A preconditioned by the factors, as :meth:`SerialLDLT.solve_refined`."""
        return ldlt.gmres(A.dot, self.solve, b, rtol, maxit)

    @property
    def flops(self) -> float:
        """Floating-point operations of the factorisation (PARDISO's Mflop report)."""
        return float(self._h.iparm[18]) * 1e6
