"""The nonlinear equations of one simulation, R(u; lam) = F_int(u) - lam f_ext = 0 with the
constraints u = lam g on the constrained dofs, at the current state u.

:class:`Equations` owns the state (u, the residual b, the external force f_ext, the work
vectors rhs, du and lift) and is what the Newton loop, the predictors and the load stepper share;
how things are assembled is the :class:`~fem_sim.solver.assembly.Assembler`'s business.
Every method is collective.
"""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI

from fem_sim.material.ogden import OgdenMaterial
from fem_sim.solver import dolfinx_compat as dc
from fem_sim.solver.assembly import Assembler, Jacobian
from fem_sim.solver.discretisation import Discretisation, DofConstraints
from fem_sim.solver.loads import Constraint


class Equations:
    """R(u; lam) and its Jacobian at the current state of one simulation (collective)."""

    def __init__(self, disc: Discretisation, assembler: Assembler):
        self.disc, self.assembler = disc, assembler
        self.u = disc.u
        self.b = disc.new_vector()      # the residual R (constrained rows zeroed)
        self.f_ext = self.b.duplicate()  # external force at load fraction 1
        self.rhs = self.b.duplicate()    # right-hand side of the next linear solve
        self.du = self.b.duplicate()     # its solution
        self.lift = self.b.duplicate()   # prescribed minus current values, constrained dofs
        self.cons: DofConstraints | None = None
        self.f_norm = 0.0
        self._blocks: dict[bytes, np.ndarray] = {}   # dof blocks of the node sets asked

    # ------------------------------------------------------------------------------------------
    def set_problem(self, material: OgdenMaterial, constraints: list[Constraint],
                    loads: list) -> None:
        self.assembler.material = material
        self.cons = self.disc.constraints(constraints)
        self.f_norm = self.disc.load_vector(loads, self.f_ext)

    @property
    def n_owned_dofs(self) -> int:
        return self.b.array_r.size

    @property
    def min_J(self) -> float:
        return self.assembler.min_J

    def state(self) -> np.ndarray:
        return self.u.x.array.copy()

    def set_state(self, arr: np.ndarray) -> None:
        """Overwrite u; the point values no longer belong to it."""
        self.u.x.array[:] = arr
        self.assembler.tangent_fresh = False

    def scatter(self) -> None:
        dc.scatter_forward(self.u)

    def update_points(self, tangent: bool = False) -> bool:
        return self.assembler.update_points(tangent)

    # ------------------------------------------------------------------------------------------
    def residual(self, lam: float) -> float:
        """B = F_int(u) - lam f_ext with constrained rows zeroed; returns |b|."""
        self.assembler.internal_forces(self.b)
        self.b.axpy(-lam, self.f_ext)
        self.b.array[self.cons.owned] = 0.0
        r = self.b.norm()
        return r if np.isfinite(r) else math.inf

    def energy(self, lam: float) -> float:
        """Potential energy: strain energy minus the work of the (dead) loads."""
        return self.assembler.strain_energy() - lam * self.f_ext.dot(self.u.vector)

    def constraint_gap(self, lam: float) -> float:
        """Set lift = prescribed - current at the constrained owned dofs; return max |gap|."""
        c = self.cons
        gap = lam * c.values_owned - self.u.x.array[c.owned]
        with self.lift.localForm() as loc:
            loc.set(0.0)
        self.lift.array[c.owned] = gap
        local = float(np.abs(gap).max()) if gap.size else 0.0
        return self.disc.comm.allreduce(local, op=MPI.MAX)

    def jacobian(self, lift: bool) -> Jacobian:
        """J at u and rhs = -R. With ``lift``, the Newton update also closes the constraint
        gap (see :meth:`constraint_gap`), accounted for in the free rows.
        """
        if not self.assembler.tangent_fresh:
            self.assembler.update_points(tangent=True)  # the tangent only when needed
        self.set_rhs_to_minus_residual()
        if lift:
            return self.assembler.jacobian(self.cons, self.rhs, self.lift)
        return self.assembler.jacobian(self.cons)

    def set_rhs_to_load(self) -> None:
        """Rhs = f_ext with constrained rows zeroed: J^-1 rhs is du/dlam."""
        self.rhs.array[:] = self.f_ext.array_r
        self.rhs.array[self.cons.owned] = 0.0

    def set_rhs_to_minus_residual(self) -> None:
        self.b.copy(self.rhs)
        self.rhs.scale(-1.0)

    # ------------------------------------------------------------------------------------------
    def save(self) -> tuple:
        """The state a rejected trial step must give back (u, point values, residual)."""
        return self.u.x.array.copy(), self.assembler.save_points(), self.b.array.copy()

    def restore(self, saved: tuple) -> None:
        u, points, b = saved
        self.u.x.array[:] = u
        self.assembler.restore_points(points)
        self.b.array[:] = b

    def reaction(self, nodes) -> np.ndarray:
        """Total internal force (N) on the dofs of a node set: the reaction force when the set
        is constrained (same value on every rank).
        """
        if not hasattr(self, "_fint"):   # a vector of its own: the residual b is kept
            self._fint = self.b.duplicate()
        self.assembler.update_points(tangent=False)
        self.assembler.internal_forces(self._fint)
        fint = self._fint.array.reshape(-1, 3)
        key = np.asarray(nodes, dtype=np.int64).tobytes()
        if key not in self._blocks:   # a tool's patch is asked at every stored step
            if len(self._blocks) >= 8:
                self._blocks.clear()
            self._blocks[key] = self.disc.node_blocks(nodes)
        blocks = self._blocks[key]
        local = fint[blocks].sum(axis=0) if blocks.size else np.zeros(3)
        return self.disc.comm.allreduce(local, op=MPI.SUM)
