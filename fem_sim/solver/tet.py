"""Lagrange tetrahedra (P1 with one quadrature point, P2 with four) in C, for the serial solver:
deformation gradients from the displacements, internal forces from the stresses, and the
Jacobian assembled into a fixed CSR pattern. Faster than dolfinx's generic assembly with the
constraints applied (``bench/bench_jacobian.py`` measures both), and the values go straight
to the factorisation without a PETSc matrix in between; F and the forces replace dolfinx's
expression evaluation and vector assembly.
``tests/fem_sim/test_verification.py`` checks all three against dolfinx for P1 and P2.

Threads (OpenMP, the point kernels' count: :func:`threads`): the cells are coloured so that no
two cells of a colour share a node, and each colour is split among the threads; results are
the same bit for bit on any number of threads. The element stiffness uses its symmetry.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fem_sim import cext

SOURCE = cext.Path(__file__).with_name("tet_kernel.c")
CDEF = """
int tet_colour(int ncells, int nn, int nnodes, const int32_t *cells, int32_t *colour);
int tet_stiffness(int ncells, int nn, int nq, const double *dN_all, const double *w_all,
                  const double *A_all, const int32_t *pos_all, double *values, int ncolours,
                  const int64_t *starts, const int32_t *order, int nthreads);
void tet_deformation(int ncells, int nn, int nq, const int32_t *cells, const double *dN_all,
                     const double *u, double *F_all, int nthreads);
void tet_forces(int ncells, int nn, int nq, const int32_t *cells, const double *dN_all,
                const double *w_all, const double *P_all, double *b, int ncolours,
                const int64_t *starts, const int32_t *order, int nthreads);
void csr_matvec(int64_t n, const int32_t *indptr, const int32_t *indices, const double *values,
                const double *x, double *y, int nthreads);
void anp_pairs(int64_t n, const int32_t *pos, const int32_t *node, const int32_t *p,
               const int32_t *q, const double *d, const double *g, double *values);
void anp_tangent(int64_t n, const double *C_all, const double *s1, const double *s2,
                 double *A_all, int nthreads);
void anp_g(int64_t n, const double *C_all, const double *dN_all, const double *w_ae,
           const int64_t *g_index, double *g);
"""

# Edges of the reference tetrahedron in basix's numbering: the P2 cell dofs 4..9 sit at their
# midpoints (fem_sim.solver.dolfinx_compat uses the same table for the dof -> node maps).
TET_EDGES = ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))


def load():
    return cext.load("tet", SOURCE, CDEF, "using dolfinx's assembly",
                     extra_compile_args=["-O3", "-std=c99", "-fopenmp"],
                     extra_link_args=["-fopenmp"])


def threads() -> int:
    """Threads of the kernels: the compiled Ogden kernel's count (``OMP_NUM_THREADS``, else the
    cores; the batch generator sets one per MPI rank): one setting for every point kernel.
    """
    from fem_sim.material import ogden_c

    return max(1, ogden_c.threads())


def reference_gradients(degree: int, points: np.ndarray) -> np.ndarray:
    """Gradients (nq, nn, 3) of the Lagrange shape functions on the reference tetrahedron at
    ``points`` (nq, 3), cell dofs in basix's order (vertices, then edge midpoints).

    With barycentric coordinates L0 = 1 - X - Y - Z, L1 = X, L2 = Y, L3 = Z: P1's functions are
    the L_i; P2's are L_i (2 L_i - 1) at vertex i (gradient (4 L_i - 1) grad L_i) and
    4 L_i L_j on edge (i, j) (gradient 4 (L_j grad L_i + L_i grad L_j)).
    """
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    gL = np.array([[-1.0, -1.0, -1.0], [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    nq = pts.shape[0]
    if degree == 1:
        return np.broadcast_to(gL, (nq, 4, 3)).copy()
    if degree != 2:
        raise ValueError(f"reference_gradients: degree 1 or 2, got {degree}")
    L = np.column_stack([1.0 - pts.sum(axis=1), pts])  # (nq, 4)
    out = np.empty((nq, 10, 3))
    out[:, :4] = (4.0 * L - 1.0)[:, :, None] * gL[None]
    for e, (i, j) in enumerate(TET_EDGES):
        out[:, 4 + e] = 4.0 * (L[:, j, None] * gL[i] + L[:, i, None] * gL[j])
    return out


class TetAssembler:
    """Deformation gradients, internal forces and the Jacobian (as CSR arrays indptr, indices,
    values) of a vector Lagrange problem on affine tetrahedra.

    ``cell_blocks`` (ncells, nn): the node (block) numbers of each cell's dofs in basix order;
    ``vertices`` (ncells, 4, 3): each cell's vertex coordinates in the same local order;
    ``degree`` 1 or 2; ``points``/``weights``: the reference quadrature rule (point values are
    cell-major, points in this order); ``indptr``/``indices``: the CSR pattern (sorted columns)
    of the 3 x 3-blocked matrix.
    """

    def __init__(self, cell_blocks: np.ndarray, vertices: np.ndarray, degree: int,
                 points: np.ndarray, weights: np.ndarray, indptr: np.ndarray,
                 indices: np.ndarray):
        mod = load()
        if mod is None:
            raise RuntimeError("the compiled tetrahedron assembly is unavailable")
        self.ffi, self.lib = mod.ffi, mod.lib
        cb = np.asarray(cell_blocks, dtype=np.int64)
        self.nn = cb.shape[1]
        self.cells = np.ascontiguousarray(cb, dtype=np.int32)
        x = np.asarray(vertices, dtype=np.float64)
        Jm = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=2)
        G = np.linalg.inv(Jm)  # d(reference coordinates)/dx
        dref = reference_gradients(degree, points)  # (nq, nn, 3)
        if dref.shape[1] != self.nn:
            raise ValueError(f"TetAssembler: P{degree} has {dref.shape[1]} dofs per cell, the "
                             f"cells have {self.nn}")
        self.nq = dref.shape[0]
        self.degree, self.vertices = degree, x
        self.points, self.weights = points, weights
        # dN[c, q, a, :] = dref[q, a, :] @ G[c]: physical gradients at every point.
        self.dN = np.ascontiguousarray(np.einsum("qaj,cjk->cqak", dref, G))
        self.w = np.ascontiguousarray(np.abs(np.linalg.det(Jm))[:, None]
                                      * np.asarray(weights, dtype=np.float64)[None, :])
        self.ncells = cb.shape[0]
        self.indptr = np.asarray(indptr, dtype=np.int32)
        self.indices = np.asarray(indices, dtype=np.int32)
        n = self.indptr.size - 1
        self._check_blocked(n)
        self.pos = self._positions(cb, n)
        self.values = np.zeros(self.indices.size)
        rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(self.indptr))
        self.diag = np.flatnonzero(rows == self.indices)
        if self.diag.size != n:
            raise ValueError("TetAssembler: the CSR pattern misses diagonal entries")
        self._bc_key = None
        self._colour(n)

    def _positions(self, cb: np.ndarray, n: int) -> np.ndarray:
        """(ncells, (3 nn)^2) the position of every element entry in the CSR value array.

        The pattern is made of full 3 x 3 blocks (rows 3A..3A+2 share their columns): entry
        (3A+i, 3B+k) sits at indptr[3A+i] + (offset of column 3B in row 3A) + k. Columns are
        sorted, so the block offsets come from one search over (block row, block column) keys.
        """
        nb, nn = n // 3, self.nn
        first = self.indptr[0:n:3]                     # start of each block row's first row
        bcols = self.indices // 3
        rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(self.indptr))
        rows_b = rows // 3
        row0 = np.flatnonzero((rows % 3 == 0) & (self.indices % 3 == 0))  # entries (3A, 3B)
        keys = rows_b[row0] * nb + bcols[row0]         # sorted
        want = cb[:, :, None] * nb + cb[:, None, :]     # (nc, nn, nn) block pairs
        bpos = np.searchsorted(keys, want.ravel())
        if np.any(bpos >= keys.size) or np.any(keys[np.minimum(bpos, keys.size - 1)]
                                               != want.ravel()):
            raise ValueError("TetAssembler: the CSR pattern misses element entries")
        boff = (row0[bpos] - first[rows_b[row0[bpos]]]).reshape(-1, nn, nn)  # offset in row 3A
        i = np.arange(3)
        # pos[c, a, i, b, k] = indptr[3 cb[c, a] + i] + boff[c, a, b] + k
        pos = (self.indptr[3 * cb[:, :, None] + i][:, :, :, None, None]
               + boff[:, :, None, :, None] + i[None, None, None, None, :])
        return np.ascontiguousarray(pos.reshape(-1, (3 * nn) ** 2), dtype=np.int32)

    def _colour(self, n: int) -> None:
        """Cells by colour (no two cells of a colour share a node): the threads split each
        colour, and every sum runs in the same order whatever their number.
        """
        colour = np.empty(self.ncells, dtype=np.int32)
        ncol = self.lib.tet_colour(self.ncells, self.nn, n // 3,
                                   self.ffi.cast("int32_t *", self.cells.ctypes.data),
                                   self.ffi.cast("int32_t *", colour.ctypes.data))
        if ncol < 0:  # > 256 colours (never seen) or no memory for the colouring: no threads
            colour[:], ncol = 0, 1
            self._serial = True
        else:
            self._serial = False
        self.order = np.ascontiguousarray(np.argsort(colour, kind="stable"), dtype=np.int32)
        self.starts = np.zeros(ncol + 1, dtype=np.int64)
        np.cumsum(np.bincount(colour, minlength=ncol), out=self.starts[1:])

    def _threads(self) -> int:
        return 1 if self._serial else threads()

    def _colours(self):
        p = self.ffi.cast
        return (self.starts.size - 1, p("int64_t *", self.starts.ctypes.data),
                p("int32_t *", self.order.ctypes.data), self._threads())

    @property
    def n_points(self) -> int:
        return self.ncells * self.nq

    def _check_blocked(self, n: int) -> None:
        lengths = np.diff(self.indptr)
        triples = self.indices.reshape(-1, 3) if self.indices.size % 3 == 0 else None
        if n % 3 or triples is None or not (
                np.all(lengths[0::3] == lengths[1::3]) and np.all(lengths[0::3] == lengths[2::3])
                and np.all(lengths % 3 == 0)
                and np.all(triples == triples[:, :1] + np.arange(3))
                and np.all(triples[:, 0] % 3 == 0)):
            raise ValueError("TetAssembler: the pattern is not made of 3 x 3 blocks")

    def _points(self, arr: np.ndarray, size: int, what: str) -> np.ndarray:
        arr = np.ascontiguousarray(arr, dtype=np.float64)
        if arr.shape != (self.n_points, size):
            raise ValueError(f"TetAssembler: {what} of shape {arr.shape}, expected "
                             f"({self.n_points}, {size}) (cells x points, {size})")
        return arr

    def assemble(self, A_points: np.ndarray) -> np.ndarray:
        """Values of the Jacobian from the tangents (ncells * nq, 81) at the points. The
        tangents must have major symmetry (A[iJ][kL] = A[kL][iJ], as the second derivative of
        a strain energy does): each element matrix is computed on and above its diagonal and
        mirrored, so the result is exactly symmetric.
        """
        A_points = self._points(A_points, 81, "tangents")
        self.values[:] = 0.0
        p = self.ffi.cast
        rc = self.lib.tet_stiffness(self.ncells, self.nn, self.nq,
                                    p("double *", self.dN.ctypes.data),
                                    p("double *", self.w.ctypes.data),
                                    p("double *", A_points.ctypes.data),
                                    p("int32_t *", self.pos.ctypes.data),
                                    p("double *", self.values.ctypes.data), *self._colours())
        if rc != 0:
            raise ValueError(f"TetAssembler: {self.nn} nodes per cell is more than the kernel "
                             "takes")
        return self.values

    def deformation(self, u: np.ndarray) -> np.ndarray:
        """F = I + grad u at every point, (ncells * nq, 9) row-major; ``u`` (nodes, 3)."""
        u = np.ascontiguousarray(u, dtype=np.float64)
        F = np.empty((self.n_points, 9))
        p = self.ffi.cast
        self.lib.tet_deformation(self.ncells, self.nn, self.nq,
                                 p("int32_t *", self.cells.ctypes.data),
                                 p("double *", self.dN.ctypes.data),
                                 p("double *", u.ctypes.data), p("double *", F.ctypes.data),
                                 self._threads())
        return F

    def forces(self, P: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Internal forces (3 per node) from first Piola stresses (ncells * nq, 9), into
        ``out`` (contiguous float64).
        """
        P = self._points(P, 9, "stresses")
        if not (out.flags.c_contiguous and out.dtype == np.float64):
            raise ValueError("TetAssembler.forces: out must be contiguous float64")
        out[:] = 0.0
        p = self.ffi.cast
        self.lib.tet_forces(self.ncells, self.nn, self.nq,
                            p("int32_t *", self.cells.ctypes.data),
                            p("double *", self.dN.ctypes.data), p("double *", self.w.ctypes.data),
                            p("double *", P.ctypes.data), p("double *", out.ctypes.data),
                            *self._colours())
        return out

    def integrate(self, values: np.ndarray) -> float:
        """Integral of a point field (ncells * nq,) over the mesh (the strain energy)."""
        return float(self.w.ravel() @ np.asarray(values, dtype=np.float64).ravel())

    def matrix(self) -> sp.csr_matrix:
        n = self.indptr.size - 1
        return sp.csr_matrix((self.values, self.indices, self.indptr), shape=(n, n))

    def apply_dirichlet(self, fixed: np.ndarray, rhs: np.ndarray | None = None,
                        lift: np.ndarray | None = None) -> None:
        """Rows and columns of the ``fixed`` dofs become identity. With ``lift`` (prescribed
        increments at the fixed dofs, zero elsewhere) the right-hand side ``rhs`` is corrected
        as PETSc's MatZeroRowsColumns does: rhs -= A lift on the free rows, rhs = lift on the
        fixed ones.
        """
        key = fixed.tobytes()
        if key != self._bc_key:
            n = self.indptr.size - 1
            is_fixed = np.zeros(n, dtype=bool)
            is_fixed[fixed] = True
            rows = np.repeat(np.arange(n), np.diff(self.indptr))
            self._bc_zero = np.flatnonzero(is_fixed[rows] | is_fixed[self.indices])
            self._bc_diag = self.diag[fixed]
            self._bc_key = key
        if lift is not None and rhs is not None:
            corr = self.matrix() @ lift
            free = np.ones(rhs.size, dtype=bool)
            free[fixed] = False
            rhs[free] -= corr[free]
            rhs[fixed] = lift[fixed]
        self.values[self._bc_zero] = 0.0
        self.values[self._bc_diag] = 1.0


class CsrOperator:
    """y = A x for CSR arrays (int32 indices, float64 values) with the kernels' threads:
    GMRES' matvec (scipy's runs on one thread). Measured on the real liver with P2 at 10 mm
    (71k unknowns, 5.6M entries), two threads: 1.7 ms a product alone, scipy's 3.5 ms; inside
    the solver (caches cold after a factorisation) 3.2 ms against 5.4-6 ms.
    """

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, values: np.ndarray):
        mod = load()
        if mod is None:
            raise RuntimeError("the compiled tetrahedron kernels are unavailable")
        self.ffi, self.lib = mod.ffi, mod.lib
        self.indptr = np.ascontiguousarray(indptr, dtype=np.int32)
        self.indices = np.ascontiguousarray(indices, dtype=np.int32)
        self.values = np.ascontiguousarray(values, dtype=np.float64)
        n = self.indptr.size - 1
        self.shape = (n, n)

    def dot(self, x: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float64)
        if x.shape != (self.shape[1],):
            raise ValueError(f"CsrOperator.dot: x of shape {x.shape}, expected "
                             f"({self.shape[1]},)")
        y = np.empty(self.shape[0])
        p = self.ffi.cast
        self.lib.csr_matvec(self.shape[0], p("int32_t *", self.indptr.ctypes.data),
                            p("int32_t *", self.indices.ctypes.data),
                            p("double *", self.values.ctypes.data),
                            p("double *", x.ctypes.data), p("double *", y.ctypes.data), threads())
        return y

    __matmul__ = dot


def operator(indptr: np.ndarray, indices: np.ndarray, values: np.ndarray):
    """A matrix with ``.dot``: :class:`CsrOperator` when the kernels are compiled, else scipy's."""
    if load() is None:
        return sp.csr_matrix((values, indices, indptr), shape=(indptr.size - 1,) * 2)
    return CsrOperator(indptr, indices, values)
