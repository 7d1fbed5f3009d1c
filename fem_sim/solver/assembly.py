"""Assemblers: material-point evaluation, internal forces, energy and the Jacobian.

One interface (:class:`Assembler`), two implementations:

* :class:`DolfinxAssembler`: dolfinx's generic assembly of the compiled forms (any degree, any
  number of processes); the Jacobian is a PETSc matrix.
* :class:`CAssembler`: C routines for P1 and P2 tetrahedra on one process
  (:mod:`fem_sim.solver.tet`): F from u, internal forces and the Jacobian straight into a fixed
  CSR pattern (several times faster than the generic assembly: ``bench/bench_jacobian.py``).

Both return a :class:`Jacobian` that gives its CSR arrays or a PETSc matrix, so the linear
solver (:mod:`fem_sim.solver.linear`) does not care which assembler made it. Constrained rows and
columns are replaced by identity; the prescribed-value lift goes to the right-hand side.
"""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_sim.material.ogden import OgdenMaterial, point_kernel
from fem_sim.solver import dolfinx_compat as dc
from fem_sim.solver import tet
from fem_sim.solver.discretisation import Discretisation, DofConstraints


class Jacobian:
    """An assembled Jacobian: a PETSc matrix, or CSR arrays on one process."""

    def __init__(self, mat=None, csr: tuple | None = None):
        self._mat, self._csr = mat, csr

    def csr(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(indptr, indices, values) of the local rows (one process: the whole matrix)."""
        return self._csr if self._csr is not None else self._mat.getValuesCSR()

    def mult(self, x: np.ndarray) -> np.ndarray:
        """J x for the owned rows, from x's owned entries (collective on the PETSc path)."""
        if self._csr is not None:
            return tet.operator(*self._csr).dot(x)
        xv, y = self._mat.createVecRight(), self._mat.createVecLeft()
        xv.array[:] = x
        self._mat.mult(xv, y)
        out = y.array.copy()
        xv.destroy()
        y.destroy()
        return out

    def petsc(self):
        if self._mat is None:
            raise NotImplementedError("this Jacobian was assembled into CSR arrays for the "
                                      "serial factorisation; PETSc's solvers use dolfinx's "
                                      "assembly")
        return self._mat


class Assembler:
    """Material-point evaluation and assembly on a :class:`Discretisation` (collective calls).

    ``update_points`` evaluates stress (and tangent) at every quadrature point from the current
    displacement and reports the smallest det F; the other methods use those values.
    """

    relaxable = False  # the hot-spot relaxation (relaxation.py) can solve its equations

    def __init__(self, disc: Discretisation):
        self.disc = disc
        self.material: OgdenMaterial | None = None
        self.tangent_fresh = False  # the tangent values belong to the current displacement
        self.min_J = 1.0

    def deformation_gradients(self) -> np.ndarray:
        """F at the local quadrature points, (n, 9)."""
        g = dc.eval_expression(self.disc.grad_u, self.disc.cells).reshape(-1, 9)
        g[:, ::4] += 1.0  # F = I + grad u
        return g

    def update_points(self, tangent: bool) -> bool:
        """Stress (and tangent) at every local quadrature point. False (on every rank) if any
        point has det F <= 0 or a non-finite value. Collective.
        """
        d = self.disc
        dc.scatter_forward(d.u)
        g = self.deformation_gradients()
        n = g.shape[0]
        if d.q_contiguous:
            out = (d.W_q.x.array[:n], d.P_q.x.array.reshape(-1, 9)[:n],
                   d.A_q.x.array.reshape(-1, 81)[:n] if tangent else None, np.empty(n))
        else:
            out = (np.empty(n), np.empty((n, 9)), np.empty((n, 81)) if tangent else None,
                   np.empty(n))
        W, P, A, J = point_kernel(g, self.material, tangent, out)
        if not d.q_contiguous:
            d.P_q.x.array.reshape(-1, 9)[d.q_dofs] = P
            d.W_q.x.array[d.q_dofs] = W
            if tangent:
                d.A_q.x.array.reshape(-1, 81)[d.q_dofs] = A
        self.tangent_fresh = tangent
        local_min = float(np.min(J)) if J.size else 1.0
        if not np.isfinite(local_min):
            local_min = -math.inf
        self.min_J = d.comm.allreduce(local_min, op=MPI.MIN)
        return self.min_J > 0

    def save_points(self) -> tuple:
        d = self.disc
        return d.P_q.x.array.copy(), d.W_q.x.array.copy(), self.tangent_fresh, self.min_J

    def restore_points(self, saved: tuple) -> None:
        d = self.disc
        P, W, self.tangent_fresh, self.min_J = saved
        d.P_q.x.array[:] = P
        d.W_q.x.array[:] = W

    def internal_forces(self, b) -> None:
        """B = F_int(u) (collective)."""
        dc.assemble_vector(b, self.disc.L)

    def strain_energy(self) -> float:
        return dc.assemble_scalar(self.disc.energy_form, self.disc.comm)

    def jacobian(self, cons: DofConstraints, rhs=None, lift=None) -> Jacobian:
        raise NotImplementedError


class DolfinxAssembler(Assembler):
    """dolfinx's assembly of the compiled forms into a PETSc matrix."""

    def __init__(self, disc: Discretisation):
        super().__init__(disc)
        self.A = dc.create_matrix(disc.a)
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)

    def jacobian(self, cons: DofConstraints, rhs=None, lift=None) -> Jacobian:
        """Assemble J; constrained rows/columns become identity. With ``lift`` (the missing
        part of the prescribed values), PETSc moves its column contributions into ``rhs`` and
        sets rhs = lift on the constrained rows.
        """
        dc.assemble_matrix(self.A, self.disc.a)
        if lift is not None:
            self.A.zeroRowsColumns(cons.global_, diag=1.0, x=lift, b=rhs)
        else:
            self.A.zeroRowsColumns(cons.global_, diag=1.0)
        return Jacobian(mat=self.A)


class CAssembler(Assembler):
    """C routines for P1/P2 tetrahedra at the quadrature points of the discretisation (one
    process).
    """

    relaxable = True

    def __init__(self, disc: Discretisation):
        super().__init__(disc)
        A = dc.create_matrix(disc.a)
        dc.assemble_matrix(A, disc.a)  # the pattern (an empty matrix has none)
        indptr, indices, _ = A.getValuesCSR()
        A.destroy()
        X = disc.V.tabulate_dof_coordinates()
        nn = 4 if disc.degree == 1 else 10
        cells = disc.V.dofmap.list.array.reshape(-1, nn)[: disc.n_cells]
        points, weights = dc.quadrature_rule(disc.qdeg)
        self.c = tet.TetAssembler(cells, X[cells[:, :4]], disc.degree, points, weights,
                                  indptr, indices)

    @staticmethod
    def available(disc: Discretisation) -> bool:
        return disc.comm.size == 1 and disc.degree in (1, 2) and tet.load() is not None

    def deformation_gradients(self) -> np.ndarray:
        return self.c.deformation(self.disc.u.x.array.reshape(-1, 3))

    def internal_forces(self, b) -> None:
        self.c.forces(self.disc.point_values(self.disc.P_q, 9), b.array)

    def strain_energy(self) -> float:
        return self.c.integrate(self.disc.point_values(self.disc.W_q, 1))

    def jacobian(self, cons: DofConstraints, rhs=None, lift=None) -> Jacobian:
        self.c.assemble(self.disc.point_values(self.disc.A_q, 81))
        self.c.apply_dirichlet(cons.owned, rhs.array if lift is not None else None,
                               lift.array_r if lift is not None else None)
        return Jacobian(csr=(self.c.indptr, self.c.indices, self.c.values))
