"""Static Ogden problem on a tetrahedral mesh: the public facade of the solver.

Python API, usable without the batch machinery::

    from fem_sim import OgdenProblem, OgdenMaterial, Constraint, NodalLoad
    prob = OgdenProblem(comm, points, cells, degree=1)           # collective; mesh on rank 0
    sol = prob.solve(OgdenMaterial((4.1e-3,), (10.06,), 0.82),
                     [Constraint(fixed_nodes)], [NodalLoad([1234], [[0, 0, -0.4]])],
                     fractions=[0.1, 0.2, ..., 1.0])
    sol.displacement   # (n_done, n_nodes, 3) mm, source-mesh node order, on rank 0

:class:`OgdenProblem` only wires the pieces together, each an object with one job, handed to
the others (FEBio's Newton solver and strategy objects, PETSc's SNES/KSP objects are the model):

* :class:`~fem_sim.solver.discretisation.Discretisation`: mesh, space, forms, dof maps;
* :class:`~fem_sim.solver.assembly.Assembler`: material points, forces, Jacobian (dolfinx or C);
* :class:`~fem_sim.solver.equations.Equations`: the state u and R(u; lam) of one simulation;
* :class:`~fem_sim.solver.linear.LinearSolver`: serial LDL^T or PETSc's KSP, counting its work;
* :class:`~fem_sim.solver.predictors.StepPredictor`: the start of each load step;
* :class:`~fem_sim.solver.newton.NewtonSolver`: Newton with chord steps and line search;
* :class:`~fem_sim.solver.stepping.LoadStepper`: load steps and cut-backs.

The settings (:class:`~fem_sim.solver.settings.SolverSettings`) name the pieces; forms are
compiled once per problem, and one problem serves every material and load on its mesh.
"""

from __future__ import annotations

import numpy as np

from data_spec.solver_rules import default_quadrature
from fem_sim.material.ogden import OgdenMaterial
from fem_sim.solver.anp import ANPAssembler
from fem_sim.solver.assembly import Assembler, CAssembler, DolfinxAssembler
from fem_sim.solver.discretisation import Discretisation
from fem_sim.solver.equations import Equations
from fem_sim.solver.linear import factorization_mode, make_linear_solver
from fem_sim.solver.loads import Constraint, NodalLoad, PatchLoad
from fem_sim.solver.newton import NewtonSolver
from fem_sim.solver.predictors import make_predictor
from fem_sim.solver.results import Solution, StepFailure
from fem_sim.solver.settings import SolverSettings
from fem_sim.solver.stepping import LoadStepper

__all__ = ["Constraint", "NodalLoad", "OgdenProblem", "PatchLoad", "Solution", "StepFailure"]


class OgdenProblem:
    """An Ogden body on a fixed mesh; :meth:`solve` runs one simulation (collective on
    ``comm``). ``settings``: overrides of :class:`SolverSettings` (a dict or the dataclass).
    ``element``: "lagrange" (P1/P2 by ``degree``) or "anp" (P1 with averaged nodal pressure,
    which does not lock, one rank; :mod:`fem_sim.solver.anp`; a scene's ``solver.element``).
    """

    def __init__(self, comm, points: np.ndarray | None, cells: np.ndarray | None, *,
                 degree: int = 1, quadrature_degree: int | None = None,
                 element: str = "lagrange",
                 settings: dict | SolverSettings | None = None, prefix: str = "ogden_"):
        if element not in ("lagrange", "anp"):
            raise ValueError(f"OgdenProblem: element must be 'lagrange' or 'anp' (P1 with "
                             f"averaged nodal pressure), got {element!r}")
        if not isinstance(settings, SolverSettings):
            settings = SolverSettings.from_dict(settings)
        self.settings = settings
        self.qdeg = quadrature_degree or default_quadrature(degree)
        # the rule table (data_spec.solver_rules): an unsupported combination fails now
        mode = factorization_mode(settings, comm.size, element, degree, self.qdeg)
        self.comm = comm
        self.element = element
        self.degree = degree
        self.disc = Discretisation(comm, points, cells, degree, self.qdeg)  # collective
        coords = self.disc.V.tabulate_dof_coordinates()[: self.disc.n_owned]
        self.linear = make_linear_solver(settings, comm, prefix, mode, coords)
        self.assembler = make_assembler(self.disc, csr_solver=self.linear.csr, element=element)
        self.equations = Equations(self.disc, self.assembler)
        self.newton = NewtonSolver(settings, self.equations, self.linear)
        self.predictor = make_predictor(settings, self.equations, self.linear)
        self.stepper = LoadStepper(settings, self.equations, self.newton, self.predictor,
                                   self.linear)

    @property
    def n_nodes(self) -> int:
        return self.disc.n_nodes

    @property
    def factorization(self) -> str:
        """The factorisation in use: "single", "double", "petsc" (MUMPS), or "none" (GAMG)."""
        return self.linear.name

    def solve(self, material: OgdenMaterial, constraints: list[Constraint],
              loads: list, fractions, reactions=()) -> Solution:
        """Run the load steps of one simulation from the undeformed state (collective);
        ``reactions``: node sets (a tool's grasped patch) whose reaction force (N) is kept at
        every stored step (:attr:`Solution.reaction`).
        """
        fractions = np.asarray(fractions, dtype=np.float64)
        if fractions.size == 0 or np.any(np.diff(fractions) <= 0) or fractions[0] <= 0:
            raise ValueError(f"fractions must be increasing and > 0, got {fractions}")
        self.equations.set_problem(material, constraints, loads)
        return self.stepper.run(fractions, self.displacement, reactions)

    def linear_responses(self, material: OgdenMaterial, constraints: list[Constraint],
                         loads: list[list], rtol: float = 1e-6) -> np.ndarray | None:
        """Small-strain displacements (len(loads), n_nodes, 3) mm on rank 0 (collective): the
        body linearised at u = 0 (its tangent there is the small-strain elasticity tensor of
        the material) under each entry of ``loads`` (a list of loads at fraction 1). One
        factorisation of that tangent serves every load set (each solve refined to ``rtol``);
        the state is left at u = 0.
        """
        out = self.load_expansion(material, constraints, loads, order=1, rtol=rtol)
        return None if out is None else out[:, 0]

    def load_expansion(self, material: OgdenMaterial, constraints: list[Constraint],
                       loads: list[list], order: int = 2, rtol: float = 1e-6,
                       step: float = 1e-3) -> np.ndarray | None:
        """The displacement's Taylor coefficients in the load fraction at u = 0 (collective):
        (len(loads), order, n_nodes, 3) mm on rank 0, u(lam) = lam u1 + lam^2 u2 + O(lam^3).

        Expanding F_int(u(lam)) = lam f: K u1 = f (K the tangent at u = 0, as in
        :meth:`linear_responses`) and K u2 = -1/2 D^2F_int(0)[u1, u1], the internal force's
        second derivative along u1 taken by the central difference
        (F_int(e u1) + F_int(-e u1)) / e^2 (F_int(0) = 0: the body is stress-free there), whose
        error is O(e^2) relative; ``step`` = e. The same factorisation solves both, each order's
        loads as one block (the linear solver's :meth:`solve_recurring_block`); the state is
        left at u = 0.
        """
        if order not in (1, 2):
            raise ValueError(f"load_expansion: order must be 1 or 2, got {order}")
        eqs = self.equations
        J = self._tangent_at_rest(material, constraints, loads[0] if loads else [])
        B = np.empty((len(loads), eqs.n_owned_dofs))
        for i, ld in enumerate(loads):
            self.disc.load_vector(ld, eqs.f_ext)
            eqs.set_rhs_to_load()
            B[i] = eqs.rhs.array_r
        terms = [self.linear.solve_recurring_block(J, eqs.rhs, eqs.du, B, rtol)]
        if order == 2:
            for i, u1 in enumerate(terms[0]):
                B[i] = -0.5 * self._second_derivative(u1, step)
            B[:, eqs.cons.owned] = 0.0
            terms.append(self.linear.solve_recurring_block(J, eqs.rhs, eqs.du, B, rtol))
        out = [[self.disc.gather_vertex_values(t[i].reshape(-1, 3)) for t in terms]
               for i in range(len(loads))]
        eqs.set_state(np.zeros_like(eqs.u.x.array))
        return np.array(out) if self.comm.rank == 0 and out else None

    def _tangent_at_rest(self, material: OgdenMaterial, constraints: list[Constraint],
                         loads: list):
        """The tangent at u = 0 of the problem (collective), the state left there."""
        eqs = self.equations
        eqs.set_problem(material, constraints, loads)
        eqs.set_state(np.zeros_like(eqs.u.x.array))
        eqs.update_points(tangent=True)
        return eqs.jacobian(lift=False)

    def unit_responses(self, material: OgdenMaterial, constraints: list[Constraint],
                       nodes: np.ndarray, rtol: float = 1e-6) -> np.ndarray | None:
        """Small-strain responses to a unit force at each of ``nodes`` (source ids) along x,
        y, z: (len(nodes), 3, n_nodes, 3) mm/N on rank 0 (collective), the body's Green's
        function there, as :meth:`linear_responses` of those nodal loads but solved as one
        block (the linear solver's :meth:`solve_recurring_block`); the state is left at
        u = 0.
        """
        return self.unit_responses_of(self._tangent_at_rest(material, constraints, []), nodes,
                                      rtol)

    def tangent_at_rest(self, material: OgdenMaterial, constraints: list[Constraint]):
        """The tangent at u = 0 (collective), to keep for :meth:`unit_responses_of`."""
        return self._tangent_at_rest(material, constraints, [])

    def unit_responses_of(self, J, nodes: np.ndarray, rtol: float = 1e-6) -> np.ndarray | None:
        """:meth:`unit_responses` with the tangent ``J`` of :meth:`tangent_at_rest`: its
        factorisation made at the first call and kept for the next (back-solves only).
        """
        eqs = self.equations
        nodes = np.asarray(nodes, dtype=np.int64)
        n = eqs.n_owned_dofs
        B = np.zeros((3 * nodes.size, n))
        for i, node in enumerate(nodes.tolist()):
            blk = self.disc.src_to_block.get(node)
            if blk is not None and blk < self.disc.n_owned:
                B[3 * i: 3 * i + 3, 3 * blk: 3 * blk + 3] = np.eye(3)
        B[:, eqs.cons.owned] = 0.0
        X = self.linear.solve_recurring_block(J, eqs.rhs, eqs.du, B, rtol)
        out = [self.disc.gather_vertex_values(x.reshape(-1, 3)) for x in X]
        if self.comm.rank != 0:
            return None
        return np.array(out).reshape(nodes.size, 3, self.n_nodes, 3)

    def _second_derivative(self, v: np.ndarray, step: float) -> np.ndarray:
        """D^2F_int(0)[v, v] at the owned dofs by a central difference (collective)."""
        eqs, total = self.equations, np.zeros_like(v)
        for sign in (1.0, -1.0):
            eqs.set_state(np.zeros_like(eqs.u.x.array))
            eqs.u.x.array[: v.size] = sign * step * v
            eqs.scatter()
            eqs.update_points(tangent=False)
            eqs.assembler.internal_forces(eqs.b)
            total += eqs.b.array_r[: v.size]
        return total / step**2

    def displacement(self) -> np.ndarray | None:
        """Current displacement at the mesh nodes, source order, on rank 0 (collective)."""
        return self.disc.gather_vertex_values(self.disc.u.x.array.reshape(-1, 3))

    def reaction(self, nodes) -> np.ndarray:
        """Total internal force (N) on the dofs of a node set: the reaction force when the set
        is constrained (collective; the same value on every rank).
        """
        return self.equations.reaction(nodes)

    def displacement_at(self, points: np.ndarray) -> np.ndarray:
        """Current displacement (n, 3) at arbitrary points (mm), the finite-element field
        evaluated there, on every rank (collective). Points outside the mesh get the closest
        cell's polynomial (for comparing meshes of the same surface at different sizes).
        """
        from mpi4py import MPI

        from fem_sim.solver import dolfinx_compat as dc

        vals, inside = dc.evaluate_at_points(self.disc.u, np.asarray(points, dtype=np.float64))
        comm = self.comm
        if comm.size == 1:
            return vals
        # Collective: average the ranks that own a point; extrapolate only if no rank does.
        w = inside.astype(np.float64)
        hits = comm.allreduce(w, op=MPI.SUM)
        total = comm.allreduce(vals * w[:, None], op=MPI.SUM)
        fallback = comm.allreduce(np.nan_to_num(vals), op=MPI.SUM) / comm.size
        return np.where(hits[:, None] > 0, total / np.maximum(hits, 1)[:, None], fallback)


def make_assembler(disc: Discretisation, csr_solver: bool, element: str = "lagrange") -> Assembler:
    """The C assembly where it applies (P1 or P2, one process) and the linear solver takes CSR
    arrays (the serial factorisation); dolfinx's assembly otherwise. ``element="anp"``: the P1
    tetrahedron with averaged nodal pressure (:mod:`fem_sim.solver.anp`).
    """
    if element == "anp":  # the rule table admitted it (data_spec.solver_rules)
        return ANPAssembler(disc)
    if csr_solver and CAssembler.available(disc):
        return CAssembler(disc)
    return DolfinxAssembler(disc)
