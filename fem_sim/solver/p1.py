"""P1 tetrahedra with one quadrature point, in C, for the serial solver: deformation gradients
from the displacements, internal forces from the stresses, and the Jacobian assembled into a
fixed CSR pattern: several times faster than dolfinx's generic assembly with the constraints
applied (``bench/bench_jacobian.py``), and the values go straight to the factorisation without
a PETSc matrix in between; F and the forces replace dolfinx's expression evaluation and vector
assembly.
``tests/fem_sim/test_verification.py`` checks all three against dolfinx.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fem_sim import cext

SOURCE = cext.Path(__file__).with_name("p1_kernel.c")
CDEF = """
void p1_stiffness(int ncells, const double *dN_all, const double *vol, const double *A_all,
                  const int32_t *pos_all, double *values);
void p1_deformation(int ncells, const int32_t *cells, const double *dN_all, const double *u,
                    double *F_all);
void p1_forces(int ncells, const int32_t *cells, const double *dN_all, const double *vol,
               const double *P_all, double *b);
"""


def load():
    return cext.load("p1", SOURCE, CDEF, "using dolfinx's assembly",
                     extra_compile_args=["-O2", "-std=c99"])


class P1Assembler:
    """Deformation gradients, internal forces and the Jacobian (as CSR arrays indptr, indices,
    values) of a P1 vector problem with one quadrature point per cell.

    ``cell_blocks`` (ncells, 4): the node (block) numbers of each cell's vertices, in the
    order of the cells' tangent values; ``coords`` (nblocks, 3) reference coordinates;
    ``indptr``/``indices``: the CSR pattern (sorted columns) of the 3 x 3-blocked matrix.
    """

    def __init__(self, cell_blocks: np.ndarray, coords: np.ndarray, indptr: np.ndarray,
                 indices: np.ndarray):
        mod = load()
        if mod is None:
            raise RuntimeError("the compiled P1 assembly is unavailable")
        self.ffi, self.lib = mod.ffi, mod.lib
        cb = np.asarray(cell_blocks, dtype=np.int64)
        self.cells = np.ascontiguousarray(cb, dtype=np.int32)
        x = coords[cb]  # (nc, 4, 3)
        Jm = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=2)
        G = np.linalg.inv(Jm)  # row r = gradient of the shape function of vertex r + 1
        self.dN = np.ascontiguousarray(np.concatenate([-G.sum(axis=1, keepdims=True), G],
                                                      axis=1))  # (nc, 4, 3)
        self.vol = np.ascontiguousarray(np.abs(np.linalg.det(Jm)) / 6.0)
        self.indptr = np.asarray(indptr, dtype=np.int32)
        self.indices = np.asarray(indices, dtype=np.int32)
        n = self.indptr.size - 1
        # Position of every element entry in the CSR value array. The pattern is made of full
        # 3 x 3 blocks (rows 3A..3A+2 share their columns): entry (3A+i, 3B+k) sits at
        # indptr[3A+i] + (offset of column 3B in row 3A) + k. Columns are sorted, so the
        # block offsets come from one search over (block row, block column) keys.
        self._check_blocked(n)
        nb = n // 3
        first = self.indptr[0:n:3]                     # start of each block row's first row
        bcols = self.indices // 3
        rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(self.indptr))
        rows_b = rows // 3
        row0 = np.flatnonzero((rows % 3 == 0) & (self.indices % 3 == 0))  # entries (3A, 3B)
        keys = rows_b[row0] * nb + bcols[row0]         # sorted
        want = cb[:, :, None] * nb + cb[:, None, :]     # (nc, 4, 4) block pairs
        bpos = np.searchsorted(keys, want.ravel())
        if np.any(bpos >= keys.size) or np.any(keys[np.minimum(bpos, keys.size - 1)]
                                               != want.ravel()):
            raise ValueError("P1Assembler: the CSR pattern misses element entries")
        boff = (row0[bpos] - first[rows_b[row0[bpos]]]).reshape(-1, 4, 4)  # offset in row 3A
        i = np.arange(3)
        # pos[c, a, i, b, k] = indptr[3 cb[c, a] + i] + boff[c, a, b] + k
        pos = (self.indptr[3 * cb[:, :, None] + i][:, :, :, None, None]
               + boff[:, :, None, :, None] + i[None, None, None, None, :])
        self.pos = np.ascontiguousarray(pos.reshape(-1, 144), dtype=np.int32)
        self.values = np.zeros(self.indices.size)
        self.diag = np.flatnonzero(rows == self.indices)
        if self.diag.size != n:
            raise ValueError("P1Assembler: the CSR pattern misses diagonal entries")
        self._bc_key = None

    def _check_blocked(self, n: int) -> None:
        lengths = np.diff(self.indptr)
        triples = self.indices.reshape(-1, 3) if self.indices.size % 3 == 0 else None
        if n % 3 or triples is None or not (
                np.all(lengths[0::3] == lengths[1::3]) and np.all(lengths[0::3] == lengths[2::3])
                and np.all(lengths % 3 == 0)
                and np.all(triples == triples[:, :1] + np.arange(3))
                and np.all(triples[:, 0] % 3 == 0)):
            raise ValueError("P1Assembler: the pattern is not made of 3 x 3 blocks")

    def assemble(self, A_cells: np.ndarray) -> np.ndarray:
        """Values of the Jacobian from the tangents (ncells, 81) at the cells' points."""
        A_cells = np.ascontiguousarray(A_cells, dtype=np.float64)
        if A_cells.shape != (self.vol.size, 81):
            raise ValueError(f"P1Assembler: tangents of shape {A_cells.shape}, expected "
                             f"({self.vol.size}, 81)")
        self.values[:] = 0.0
        p = self.ffi.cast
        self.lib.p1_stiffness(self.vol.size, p("double *", self.dN.ctypes.data),
                              p("double *", self.vol.ctypes.data),
                              p("double *", A_cells.ctypes.data),
                              p("int32_t *", self.pos.ctypes.data),
                              p("double *", self.values.ctypes.data))
        return self.values

    def deformation(self, u: np.ndarray) -> np.ndarray:
        """F = I + grad u per cell, (ncells, 9) row-major; ``u`` (nodes, 3) displacements."""
        u = np.ascontiguousarray(u, dtype=np.float64)
        F = np.empty((self.vol.size, 9))
        p = self.ffi.cast
        self.lib.p1_deformation(self.vol.size, p("int32_t *", self.cells.ctypes.data),
                                p("double *", self.dN.ctypes.data),
                                p("double *", u.ctypes.data), p("double *", F.ctypes.data))
        return F

    def forces(self, P: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Internal forces (3 per node) from first Piola stresses (ncells, 9), into ``out``."""
        P = np.ascontiguousarray(P, dtype=np.float64)
        if P.shape != (self.vol.size, 9) or not (out.flags.c_contiguous
                                                 and out.dtype == np.float64):
            raise ValueError("P1Assembler.forces: P must be (ncells, 9), out contiguous float64")
        out[:] = 0.0
        p = self.ffi.cast
        self.lib.p1_forces(self.vol.size, p("int32_t *", self.cells.ctypes.data),
                           p("double *", self.dN.ctypes.data), p("double *", self.vol.ctypes.data),
                           p("double *", P.ctypes.data), p("double *", out.ctypes.data))
        return out

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
