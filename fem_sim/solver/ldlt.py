"""Serial sparse LDL^T (MUMPS through its C interface) with METIS ordering, in double or
single precision, and GMRES refinement to double-precision accuracy.

Why: PETSc's MUMPS LDL^T with Debian's build can only order with PORD (or AMD/AMF/QAMD), which
need more operations than METIS nested dissection on the node graph, and single-precision
factors run at a higher flop rate (``bench/bench_jacobian.py`` prints both on the real liver;
the figures are in the README). One solve with float32 factors leaves a relative residual of
order 1e-3, so the Newton systems are solved by GMRES preconditioned with them (a few
iterations to 1e-10); chord steps and tangent predictors, approximate by nature, use one
back-solve. This is not a petsc4py python PC on purpose: PETSc objects holding Python contexts
crashed at interpreter exit.

Only for one process: under MPI with more ranks per simulation the solver uses PETSc's MUMPS.
"""

from __future__ import annotations

import atexit
import functools
import weakref

import numpy as np
from mpi4py import MPI

from fem_sim import cext
from fem_sim.solver import blas

SOURCE = cext.Path(__file__).with_name("ldlt_kernel.c")
CDEF = """
void *ldlt_new(int single, int sym);
void ldlt_set_icntl(void *h, int i, int v);
int ldlt_info(void *h, int i);
double ldlt_rinfo(void *h, int i);
int ldlt_analyse(void *h, int n, int64_t nnz, int *irn, int *jcn, int *perm_in, int mem_relax);
int ldlt_factor(void *h, void *a);
int ldlt_solve(void *h, void *rhs);
void ldlt_free(void *h);
int nested_dissection(int n, const int *xadj, const int *adj, int *perm, int *iperm);
"""
MPI_INCLUDE = ["/usr/lib/x86_64-linux-gnu/openmpi/include",
               "/usr/lib/x86_64-linux-gnu/openmpi/include/openmpi"]


@functools.lru_cache(maxsize=1)
def _mpi_flags() -> dict:
    """Include and library directories of the MPI that mpi4py uses (``mpicc --showme``)."""
    import shutil
    import subprocess

    inc, libdirs = list(MPI_INCLUDE), ["/usr/lib/x86_64-linux-gnu/openmpi/lib"]
    if shutil.which("mpicc"):
        try:
            comp = subprocess.run(["mpicc", "--showme:compile"], capture_output=True,
                                  text=True, timeout=30).stdout.split()
            link = subprocess.run(["mpicc", "--showme:link"], capture_output=True,
                                  text=True, timeout=30).stdout.split()
            inc = [a[2:] for a in comp if a.startswith("-I")] or inc
            libdirs = [a[2:] for a in link if a.startswith("-L")] or libdirs
        except (OSError, subprocess.SubprocessError):
            pass
    return {"include_dirs": tuple(inc), "library_dirs": tuple(libdirs)}


def load():
    """The compiled module, or None (then the solver uses PETSc's MUMPS, with a warning)."""
    flags = _mpi_flags()  # asked once per process (mpicc --showme)
    return cext.load("ldlt", SOURCE, CDEF, "using PETSc's MUMPS (PORD ordering, slower)",
                     extra_compile_args=["-O2", "-std=c99"],
                     libraries=["dmumps", "smumps", "mumps_common", "metis", "mpi"],
                     include_dirs=list(flags["include_dirs"]),
                     library_dirs=list(flags["library_dirs"]))


# MUMPS instances (and PARDISO's, pardiso.py) must be freed before MPI_Finalize: mpi4py
# finalises MPI in an atexit hook registered at its import, and atexit runs hooks last-in
# first-out, so ours runs first.
_live: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _free_all() -> None:
    for obj in list(_live):
        obj.free()


class FactorError(RuntimeError):
    """The factorisation failed: MUMPS reported an error (INFOG(1) < 0, e.g. -10: numerically
    singular matrix), or PARDISO did (e.g. -4: not positive definite).
    """


def block_graph(indptr: np.ndarray, indices: np.ndarray, bs: int):
    """CSR adjacency (no self loops) of the bs x bs blocks of a CSR pattern."""
    n = (indptr.size - 1) // bs
    rows = np.repeat(np.arange(indptr.size - 1, dtype=np.int64), np.diff(indptr)) // bs
    cols = indices.astype(np.int64) // bs
    off = rows != cols
    key = np.unique(rows[off] * n + cols[off])
    r, c = key // n, key % n
    xadj = np.zeros(n + 1, dtype=np.int32)
    np.add.at(xadj, r + 1, 1)
    return np.cumsum(xadj, dtype=np.int32), np.ascontiguousarray(c, dtype=np.int32)


class SerialLDLT:
    """LDL^T of a symmetric matrix given by its full CSR arrays (one process).

    ``factor(indptr, indices, values)`` analyses on the first call (and whenever the pattern
    changes), then factorises; ``solve(b)`` returns x (float64) with A x ~= b.
    ``precision``: "single" (float32 factors) or "double"; ``bs``: block size of the dofs
    (3 for displacements), the ordering is computed on the block graph; ``pivoting``: MUMPS'
    SYM=2 (2x2 pivots) or SYM=1 (none: faster; an indefinite matrix still factorises unless
    a pivot vanishes, and :attr:`negative_pivots` still gives its inertia).
    """

    def __init__(self, precision: str = "single", bs: int = 3, pivoting: bool = True):
        if precision not in ("single", "double"):
            raise ValueError(f"precision must be 'single' or 'double', got {precision!r}")
        mod = load()
        if mod is None:
            raise RuntimeError("the compiled LDL^T extension is unavailable")
        self.ffi, self.lib = mod.ffi, mod.lib
        self.dtype = np.float32 if precision == "single" else np.float64
        self.bs = bs
        self._h = self.lib.ldlt_new(int(precision == "single"), 2 if pivoting else 1)
        if self._h == self.ffi.NULL:
            raise MemoryError("ldlt_new failed")
        if not pivoting:
            # No pivot choice to guide, so no scaling (ICNTL(8) = 0). Measured on the real
            # liver's Jacobian, float32: 1.00 s against 1.05 s with OpenBLAS' SSE3 kernels,
            # equal (0.47 s) with its AVX-512 ones.
            self.lib.ldlt_set_icntl(self._h, 8, 0)
        self._pattern = None
        self._like: SerialLDLT | None = None  # share_ordering
        self._perm_in = None
        _live.add(self)
        self.analyses = self.factorizations = 0

    def free(self) -> None:
        """Release MUMPS' memory (also at garbage collection, and at exit while MPI is up)."""
        h = getattr(self, "_h", None)
        self._h = None
        if h is not None and not MPI.Is_finalized():
            self.lib.ldlt_free(h)

    __del__ = free

    def _check(self, what: str) -> None:
        code = self.lib.ldlt_info(self._h, 1)
        if code < 0:
            raise FactorError(f"MUMPS {what} failed: INFOG(1) = {code}, INFOG(2) = "
                              f"{self.lib.ldlt_info(self._h, 2)}")

    def _ptr(self, arr: np.ndarray, ctype: str):
        return self.ffi.cast(ctype, arr.ctypes.data)

    def share_ordering(self, other: SerialLDLT) -> None:
        """Take ``other``'s ordering (and triangle arrays) when this instance analyses the
        pattern ``other`` analysed: one METIS run for several instances of one pattern.
        """
        self._like = other

    def _same_pattern(self, indptr: np.ndarray, indices: np.ndarray) -> bool:
        return self._pattern is not None and np.array_equal(self._pattern[0], indptr) \
            and np.array_equal(self._pattern[1], indices)

    def _analyse(self, indptr: np.ndarray, indices: np.ndarray) -> None:
        n = indptr.size - 1
        like = self._like
        perm_in = self.ffi.NULL  # not blocked: MUMPS' own choice (AMD)
        if like is not None and like.bs == self.bs and like._same_pattern(indptr, indices):
            self._upper, self._irn, self._jcn = like._upper, like._irn, like._jcn
            if like._perm_in is not None:
                self._perm_in = like._perm_in
                perm_in = self._ptr(self._perm_in, "int *")
        else:
            perm_in = self._order(indptr, indices)
        self.lib.ldlt_analyse(self._h, n, self._irn.size, self._ptr(self._irn, "int *"),
                              self._ptr(self._jcn, "int *"), perm_in, 100)
        self._check("analysis")
        self._pattern = (indptr.copy(), indices.copy())
        self.analyses += 1

    def _order(self, indptr: np.ndarray, indices: np.ndarray):
        """The upper-triangle arrays and METIS' nested dissection of the block graph; returns
        MUMPS' PERM_IN pointer (NULL: MUMPS orders).
        """
        n = indptr.size - 1
        rows = np.repeat(np.arange(n, dtype=np.int32), np.diff(indptr))
        self._upper = indices >= rows
        self._irn = np.ascontiguousarray(rows[self._upper] + 1, dtype=np.int32)
        self._jcn = np.ascontiguousarray(indices[self._upper] + 1, dtype=np.int32)
        self._perm_in = None
        perm_in = self.ffi.NULL
        if n % self.bs == 0:
            xadj, adj = block_graph(indptr, indices, self.bs)
            nb = xadj.size - 1
            perm, iperm = np.empty(nb, np.int32), np.empty(nb, np.int32)
            status = self.lib.nested_dissection(nb, self._ptr(xadj, "int *"),
                                                self._ptr(adj, "int *"),
                                                self._ptr(perm, "int *"),
                                                self._ptr(iperm, "int *"))
            if status != 1:
                raise FactorError(f"METIS_NodeND failed with status {status}")
            # MUMPS' PERM_IN(i) is the (1-based) pivot position of variable i.
            self._perm_in = (self.bs * iperm[:, None] + np.arange(self.bs)).ravel() + 1
            self._perm_in = np.ascontiguousarray(self._perm_in, dtype=np.int32)
            perm_in = self._ptr(self._perm_in, "int *")
        return perm_in

    def factor(self, indptr: np.ndarray, indices: np.ndarray, values: np.ndarray) -> None:
        if not self._same_pattern(indptr, indices):
            self._analyse(indptr, indices)
        self._a = np.ascontiguousarray(values[self._upper], dtype=self.dtype)
        with blas.outer():  # the fronts are level-3 BLAS: the process's threads
            self.lib.ldlt_factor(self._h, self._ptr(self._a, "void *"))
        self.factorizations += 1
        self._check("factorisation")

    def solve(self, b: np.ndarray) -> np.ndarray:
        """One back-solve with the factors (float64 result; ~1e-3 relative error in single)."""
        x = np.array(b, dtype=self.dtype)
        self.lib.ldlt_solve(self._h, self._ptr(x, "void *"))
        self._check("solve")
        return x.astype(np.float64)

    def solve_block(self, b: np.ndarray) -> np.ndarray:
        """Back-solves of the rows of ``b`` (k, n), one by one."""
        return np.stack([self.solve(row) for row in b]) if len(b) else np.zeros_like(b)

    def solve_refined(self, A, b: np.ndarray, rtol: float, maxit: int = 30):
        """Solve A x = b to |b - A x| <= rtol |b| in float64: GMRES preconditioned (on the
        right) by the factors. A is the factorised matrix (double-precision factors usually
        need one iteration, single-precision ones 2-4: each contracts the residual ~1e3 times)
        or a nearby one (the factors of an older Jacobian for a newer one).
        Returns (x, iterations, converged).
        """
        return gmres(A.dot, self.solve, b, rtol, maxit)

    @property
    def negative_pivots(self) -> int:
        """Negative eigenvalues of D (the inertia of the last factorised matrix)."""
        return int(self.lib.ldlt_info(self._h, 12))

    @property
    def flops(self) -> float:
        """Floating-point operations of the last factorisation (MUMPS' RINFOG(3))."""
        return float(self.lib.ldlt_rinfo(self._h, 3))


def csr(indptr, indices, values):
    import scipy.sparse as sp

    n = indptr.size - 1
    return sp.csr_matrix((values, indices, indptr), shape=(n, n))


def gmres(matvec, precond, b: np.ndarray, rtol: float, maxit: int):
    """Right-preconditioned GMRES from x = 0, without restarts (modified Gram-Schmidt with one
    re-orthogonalisation). Stops when the true residual |b - A x| <= rtol |b|.
    Returns (x, iterations, converged).

    The least-squares residual |beta e1 - H y| is |b - A x| in exact arithmetic (right
    preconditioning: x = Z y); it decides when to look, and the true residual (one more
    matvec) decides whether to stop. Checking the true residual at every iteration cost a
    matvec per iteration: on the real liver with P2 (71k unknowns) 242 matvecs instead of ~130
    per simulation, with the same iterations.
    """
    bnorm = float(np.linalg.norm(b))
    if bnorm == 0.0:
        return np.zeros_like(b), 0, True
    V = [b / bnorm]
    Z = []
    H = np.zeros((maxit + 1, maxit))
    x = np.zeros_like(b)
    for k in range(maxit):
        z = precond(V[k])
        if not np.all(np.isfinite(z)):
            return x, k, False
        Z.append(z)
        w = matvec(z)
        for _ in range(2):
            for j in range(k + 1):
                h = float(V[j] @ w)
                H[j, k] += h
                w -= h * V[j]
        H[k + 1, k] = float(np.linalg.norm(w))
        e1 = np.zeros(k + 2)
        e1[0] = bnorm
        Hk = H[: k + 2, : k + 1]
        y = np.linalg.lstsq(Hk, e1, rcond=None)[0]
        breakdown = H[k + 1, k] <= 1e-14 * bnorm
        estimate = float(np.linalg.norm(e1 - Hk @ y))
        if estimate <= rtol * bnorm or breakdown or k + 1 == maxit:
            x = sum(yi * zi for yi, zi in zip(y, Z))
            if float(np.linalg.norm(b - matvec(x))) <= rtol * bnorm:
                return x, k + 1, True
            if breakdown:
                return x, k + 1, False  # breakdown without convergence
        V.append(w / H[k + 1, k])
    return x, maxit, False
