"""Static Ogden problem on a tetrahedral mesh: Newton with line search and load stepping.

Python API, usable without the batch machinery::

    from fem_sim import OgdenProblem, OgdenMaterial, Constraint, NodalLoad
    prob = OgdenProblem(comm, points, cells, degree=1)           # collective; mesh on rank 0
    sol = prob.solve(OgdenMaterial((4.1e-3,), (10.06,), 0.82),
                     [Constraint(fixed_nodes)], [NodalLoad([1234], [[0, 0, -0.4]])],
                     fractions=[0.1, 0.2, ..., 1.0])
    sol.displacement   # (n_done, n_nodes, 3) mm, source-mesh node order, on rank 0

Design (measured choices; bench/ has the numbers):

* Material stress and tangent are evaluated at quadrature points in numpy
  (:mod:`fem_sim.ogden`, exact at coinciding stretches) and enter two compiled forms as
  quadrature-space coefficients. Forms are compiled once per problem; materials and loads are
  numpy data, so one problem serves every simulation on the same mesh.
* Each Newton iteration assembles the exact Jacobian and factorises it. On one process the
  factorisation is MUMPS' LDL^T through its C interface, ordered with METIS nested dissection
  and in float32, the Newton system then solved to full accuracy by GMRES preconditioned with
  it (:mod:`fem_sim.ldlt`: 0.65 s instead of PETSc's 1.26 s per factorisation on the real
  liver at 15k nodes, ``bench/bench_jacobian.py``); on several processes PETSc's MUMPS LDL^T
  (PORD ordering). Optionally (``lag_factorization``) the factorisation is lagged and used
  as a GMRES preconditioner; in development runs it was slower at 15k nodes on the real
  liver, where the strongly nonlinear point-load response makes stale factorisations poor
  preconditioners (5 of 10 solves needed a new one after 12 iterations). So it is off by
  default.
* Between Newton steps, chord steps (back-solves with the last factorisation) are taken while
  they contract |R| 10x each (see :meth:`OgdenProblem._newton`).
* Load steps start from a Hermite predictor: at every converged state u_k the tangent
  du/dlambda = J(u_k)^-1 f is computed (J assembled there, GMRES preconditioned with the last
  factorisation), and the next state is predicted by the polynomial of degree 2m-1 through the
  last m = 3 states and tangents. Its error falls as h^(2m) (tested); on the real liver it is
  1e-3 to 1e-5 of the increment, and most steps then need one Newton step plus chord steps:
  15 factorisations per simulation against 26 with the former predictor (integrating the
  tangents of the last Newton iterations), 42 for textbook Newton (``bench/bench_solver.py``).
  If Newton fails from the prediction, the increment is retried from the last converged state
  before cutting back.
* A step fails on: NaN/inf, det F <= 0 at any quadrature point, a linear-solver failure, a
  line search that cannot reduce the residual, or too many iterations. It is then retried with
  half the increment (up to ``max_cutbacks`` halvings per output step); successful small steps
  let the increment grow again. Nothing is ever returned for a step that did not converge.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from fem_sim import dolfinx_compat as dc
from fem_sim import ldlt, p1
from fem_sim.ogden import OgdenMaterial, point_kernel

log = logging.getLogger(__name__)

DEFAULT_SETTINGS = {
    "rtol": 1e-9,            # Newton: |R| <= max(atol, rtol * force scale)
    "atol": 1e-10,           # N
    "max_iterations": 25,    # Newton iterations per increment attempt
    "max_cutbacks": 8,       # increment halvings per output step
    "linear_solver": "mumps",  # "mumps" (direct LDL^T) or "gamg" (CG + GAMG)
    "factorization": "auto",  # mumps: "single" (float32 LDL^T, METIS; GMRES to krylov_rtol),
                              # "double" (float64, METIS), "petsc" (PETSc's MUMPS, PORD);
                              # "auto": "single" on one process, "petsc" on several
    "lag_factorization": False,  # True: GMRES with a lagged factorisation as preconditioner
    "krylov_rtol": 1e-10,    # relative tolerance of each linear solve
    "refactor_after": 8,     # refactorise when a solve needs more Krylov iterations
    "max_krylov": 60,        # Krylov iterations before the solve counts as failed
    "predictor": "hermite",  # Hermite polynomial through the last converged states and their
                             # tangents du/dlam = J^-1 f; "tangent" (integrate the tangents of
                             # the last Newton iterations); "extrapolate" (previous states);
                             # "previous" (start from the last converged state)
    "predictor_order": 3,    # hermite: points used (1 = Euler); tangent: tangents used
    "line_search": True,
    "chord_contraction": 0.1,  # keep back-solving with the last factorisation while |R| drops
                               # by this factor per step (0 disables chord steps)
    "chord_trigger": 1e-2,   # try chord steps after a Newton step that cut |R| this much
    "max_chord_steps": 30,   # chord steps per increment attempt
    "petsc_options": {},     # overrides, without the prefix
}
# Tangents for the Hermite predictor: solved to this accuracy (the predictor error is ~1e-5 of
# the increment, measured), by GMRES with the last factorisation as preconditioner, which is
# refactorised if GMRES needs more than TANGENT_MAX_GMRES iterations.
TANGENT_RTOL = 1e-8
TANGENT_MAX_GMRES = 12


@dataclass
class Constraint:
    """Prescribed displacement of source nodes: ``values`` (mm, at load fraction 1) for the
    given components. The default is a fixed (zero-displacement) node set.
    """

    nodes: np.ndarray
    components: tuple[int, ...] = (0, 1, 2)
    values: float | np.ndarray = 0.0


@dataclass
class NodalLoad:
    """Forces (N, at load fraction 1) on source nodes; repeated nodes add up."""

    nodes: np.ndarray
    forces: np.ndarray

    def __post_init__(self):
        self.nodes = np.atleast_1d(np.asarray(self.nodes, dtype=np.int64))
        self.forces = np.asarray(self.forces, dtype=np.float64).reshape(-1, 3)
        if self.nodes.shape[0] != self.forces.shape[0]:
            raise ValueError(f"NodalLoad: {self.nodes.shape[0]} nodes but "
                             f"{self.forces.shape[0]} force vectors")
        if not np.all(np.isfinite(self.forces)):
            raise ValueError("NodalLoad: forces contain NaN or inf")


@dataclass
class PatchLoad:
    """A total force (N, at load fraction 1) spread as a traction over the boundary around a
    centre point: t(x) = force w(x) / integral(w ds), with the footprint
    w = (1 - (d / radius)^2)^2 for d = |x - centre| < radius ("bump", smooth, an indenter's
    pressure profile) or w = 1 inside ("uniform"). The applied total force is exactly ``force``
    and the load is a proper surface integral, so it converges under refinement (P1 and P2),
    unlike a point force.
    """

    centre: np.ndarray
    force: np.ndarray
    radius: float
    profile: str = "bump"

    def __post_init__(self):
        self.centre = np.asarray(self.centre, dtype=np.float64).reshape(3)
        self.force = np.asarray(self.force, dtype=np.float64).reshape(3)
        if not (np.all(np.isfinite(self.force)) and np.all(np.isfinite(self.centre))):
            raise ValueError("PatchLoad: NaN or inf in centre or force")
        if not self.radius > 0 or self.profile not in ("bump", "uniform"):
            raise ValueError("PatchLoad: radius must be > 0 and profile 'bump' or 'uniform'")

    def weight(self, x: np.ndarray) -> np.ndarray:
        d2 = np.sum((x - self.centre) ** 2, axis=1) / self.radius**2
        if self.profile == "uniform":
            return (d2 <= 1.0).astype(np.float64)
        return np.clip(1.0 - d2, 0.0, None) ** 2


@dataclass
class Solution:
    """Result of :meth:`OgdenProblem.solve`. Arrays per *stored* output step."""

    fractions: np.ndarray
    displacement: np.ndarray | None  # (n_done, n_nodes, 3) on the comm's rank 0, else None
    newton_iterations: list[int] = field(default_factory=list)
    residual_norms: list[float] = field(default_factory=list)
    cutbacks: list[int] = field(default_factory=list)
    wall_time: list[float] = field(default_factory=list)
    residual_history: list[list[float]] = field(default_factory=list)
    status: str = "ok"
    failure_reason: str = ""
    factorizations: int = 0
    krylov_iterations: int = 0
    chord_steps: int = 0      # accepted back-solves with an old factorisation
    chord_rejected: int = 0   # chord steps tried and undone (too little contraction)
    double_fallbacks: int = 0  # float32 factorisations that had to be redone in float64

    @property
    def n_done(self) -> int:
        return len(self.newton_iterations)


class StepFailure(Exception):
    """An increment that did not converge; the message is the recorded reason."""


def _flat(T):
    return ufl.as_vector([T[i, j] for i in range(3) for j in range(3)])


class OgdenProblem:
    """An Ogden body on a fixed mesh; solve() runs one simulation (collective on ``comm``)."""

    def __init__(self, comm, points: np.ndarray | None, cells: np.ndarray | None, *,
                 degree: int = 1, quadrature_degree: int | None = None,
                 settings: dict | None = None, prefix: str = "ogden_"):
        unknown = set(settings or {}) - set(DEFAULT_SETTINGS)
        if unknown:
            raise ValueError(f"OgdenProblem: unknown settings {sorted(unknown)}; expected "
                             f"some of {sorted(DEFAULT_SETTINGS)}")
        self.settings = {**DEFAULT_SETTINGS, **(settings or {})}
        self.comm = comm
        self.degree = degree
        self.qdeg = quadrature_degree or (1 if degree == 1 else 2)
        self.prefix = prefix
        self._own_mode = self._own_factorization()  # validates settings.factorization
        # Collective: distribute the mesh, build spaces and compile forms.
        n_nodes = points.shape[0] if comm.rank == 0 else None
        self.n_nodes = comm.bcast(n_nodes, root=0)
        self.mesh = dc.create_mesh(comm, points, cells)
        self.V = dc.vector_space(self.mesh, degree)
        self.u = dc.fem.Function(self.V)
        self.n_cells = dc.num_local_cells(self.mesh)
        self.cells = np.arange(self.n_cells, dtype=np.int32)
        self.P_q = dc.quadrature_function(self.mesh, self.qdeg, (9,))
        self.A_q = dc.quadrature_function(self.mesh, self.qdeg, (9, 9))
        self.W_q = dc.quadrature_function(self.mesh, self.qdeg, (1,))
        self.q_dofs = dc.quadrature_cell_dofs(self.P_q, self.n_cells).ravel()
        # Quadrature dofs numbered cell by cell (the usual case): the kernel writes straight
        # into the coefficient arrays.
        self._q_contiguous = np.array_equal(self.q_dofs, np.arange(self.q_dofs.size))
        v, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        dx = ufl.dx(metadata={"quadrature_degree": self.qdeg})
        self.L = dc.compile_form(ufl.inner(self.P_q, _flat(ufl.grad(v))) * dx)
        self.energy_form = dc.compile_form(self.W_q[0] * dx)
        self.a = dc.compile_form(
            ufl.inner(ufl.dot(self.A_q, _flat(ufl.grad(du))), _flat(ufl.grad(v))) * dx)
        self.grad_u = dc.compile_expression(ufl.grad(self.u), dc.quadrature_points(self.qdeg))
        # Patch loads: traction t w(x) on the boundary, w a finite-element footprint function.
        self.w = dc.fem.Function(dc.scalar_space(self.mesh, degree))
        self.t = dc.constant(self.mesh, np.zeros(3))
        ds = ufl.ds(metadata={"quadrature_degree": 2 * degree})
        self.L_patch = dc.compile_form(ufl.inner(self.t * self.w, v) * ds)
        self.patch_area = dc.compile_form(self.w * ds)
        self.A = dc.create_matrix(self.a)
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        self.Pmat = None
        self.b = dc.create_vector(self.L)
        self.f_ext = self.b.duplicate()
        self.du = self.b.duplicate()
        self.rhs = self.b.duplicate()
        self.lift = self.b.duplicate()
        self.n_owned = dc.owned_size(self.V)
        blocks, src = dc.vertex_dof_source_ids(self.mesh, self.V)
        self.vertex_blocks, self.vertex_src = blocks, src
        owned = blocks < self.n_owned
        self.owned_vertex_blocks, self.owned_vertex_src = blocks[owned], src[owned]
        self.src_to_block = dict(zip(src.tolist(), blocks.tolist()))
        self._ksp = None
        self._ldlt: ldlt.SerialLDLT | None = None  # the one holding the last factorisation
        self._ldlts: dict[str, ldlt.SerialLDLT] = {}  # by precision
        self.material: OgdenMaterial | None = None
        self.min_J = 1.0
        self._tangent_fresh = False
        self._factorized = False
        self._predicted_order = 0
        self._p1 = self._build_p1()  # C routines for P1 one-point cells, or None

    # ------------------------------------------------------------------------------------------
    # Pieces of one Newton iteration
    # ------------------------------------------------------------------------------------------
    def _update_points(self, tangent: bool) -> bool:
        """Evaluate stress (and tangent) at every quadrature point of the local cells.

        Returns False (on every rank) if any point has det F <= 0 or a non-finite value.
        Collective (the verdict is reduced over the communicator).
        """
        dc.scatter_forward(self.u)
        if self._p1 is not None:  # one point per cell, cells in order: F straight from C
            g = self._p1.deformation(self.u.x.array.reshape(-1, 3))
        else:
            g = dc.eval_expression(self.grad_u, self.cells).reshape(-1, 9)
            g[:, ::4] += 1.0  # F = I + grad u
        n = g.shape[0]
        if self._q_contiguous:
            out = (self.W_q.x.array[:n], self.P_q.x.array.reshape(-1, 9)[:n],
                   self.A_q.x.array.reshape(-1, 81)[:n] if tangent else None, np.empty(n))
        else:
            out = (np.empty(n), np.empty((n, 9)), np.empty((n, 81)) if tangent else None,
                   np.empty(n))
        W, P, A, J = point_kernel(g, self.material, tangent, out)
        if not self._q_contiguous:
            self.P_q.x.array.reshape(-1, 9)[self.q_dofs] = P
            self.W_q.x.array[self.q_dofs] = W
            if tangent:
                self.A_q.x.array.reshape(-1, 81)[self.q_dofs] = A
        self._tangent_fresh = tangent
        local_min = float(np.min(J)) if J.size else 1.0
        if not np.isfinite(local_min):
            local_min = -math.inf
        self.min_J = self.comm.allreduce(local_min, op=MPI.MIN)
        return self.min_J > 0

    def _residual(self, lam: float) -> float:
        """B = F_int(u) - lam f_ext with constrained rows zeroed; returns |b| (collective)."""
        if self._p1 is not None:
            self._p1.forces(self._cell_values(self.P_q, 9), self.b.array)
        else:
            dc.assemble_vector(self.b, self.L)
        self.b.axpy(-lam, self.f_ext)
        self.b.array[self._fixed_owned] = 0.0
        r = self.b.norm()
        return r if np.isfinite(r) else math.inf

    def _energy(self, lam: float) -> float:
        """Potential energy: strain energy minus the work of the (dead) loads (collective)."""
        if self._p1 is not None:
            strain = float(self._p1.vol @ self._cell_values(self.W_q, 1)[:, 0])
        else:
            strain = dc.assemble_scalar(self.energy_form, self.comm)
        return strain - lam * self.f_ext.dot(self.u.vector)

    def _cell_values(self, q: dc.fem.Function, size: int) -> np.ndarray:
        """Values of a one-point quadrature function, cell by cell: (ncells, size)."""
        arr = q.x.array.reshape(-1, size)
        return arr[: self.n_cells] if self._q_contiguous else arr[self.q_dofs]

    def _jacobian(self, lift: float) -> None:
        """Assemble J and the right-hand side -R (collective).

        Constrained rows/columns become identity; ``self.lift`` carries the missing part of the
        prescribed values (target - current), which PETSc moves to the right-hand side, so the
        Newton update both satisfies the constraints and accounts for them in the free rows.
        """
        if not self._tangent_fresh:
            self._update_points(tangent=True)  # the tangent is evaluated only when needed
        if self._p1 is not None:
            self._p1.assemble(self._cell_values(self.A_q, 81))
            self.b.copy(self.rhs)
            self.rhs.scale(-1.0)
            self._p1.apply_dirichlet(self._fixed_owned, self.rhs.array if lift else None,
                               self.lift.array_r if lift else None)
            return
        dc.assemble_matrix(self.A, self.a)
        self.b.copy(self.rhs)
        self.rhs.scale(-1.0)
        if lift:
            self.A.zeroRowsColumns(self._fixed_global, diag=1.0, x=self.lift, b=self.rhs)
        else:
            self.A.zeroRowsColumns(self._fixed_global, diag=1.0)

    def _build_p1(self) -> p1.P1Assembler | None:
        """The C routines for P1 cells with one quadrature point (:mod:`fem_sim.p1`: F from u,
        internal forces, the Jacobian into CSR arrays), used with the serial factorisation;
        None when dolfinx assembles (P2, several ranks, PETSc's solvers).
        """
        if not (self._own_mode and self.degree == 1 and self.qdeg == 1
                and p1.load() is not None):
            return None
        dc.assemble_matrix(self.A, self.a)  # the pattern (an empty matrix has none)
        indptr, indices, _ = self.A.getValuesCSR()
        cells = self.V.dofmap.list.array.reshape(-1, 4)[: self.n_cells]
        coords = self.V.tabulate_dof_coordinates()
        return p1.P1Assembler(cells, coords, indptr, indices)

    def jacobian_csr(self):
        """The last assembled Jacobian (with the constraint rows/columns) as CSR arrays
        (indptr, indices, values); one process only.
        """
        if self._p1 is not None:
            return self._p1.indptr, self._p1.indices, self._p1.values
        return self.A.getValuesCSR()

    def _linear_solver(self) -> PETSc.KSP:
        if self._ksp is not None:
            return self._ksp
        s = self.settings
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOptionsPrefix(self.prefix)
        opts = PETSc.Options()
        if s["linear_solver"] == "mumps":
            defaults = {"ksp_type": "gmres" if s["lag_factorization"] else "preonly",
                        "ksp_gmres_restart": 100,
                        "pc_type": "cholesky", "pc_factor_mat_solver_type": "mumps",
                        "mat_mumps_icntl_14": 200}
        else:
            defaults = {"ksp_type": "cg", "pc_type": "gamg", "pc_gamg_type": "agg",
                        "mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi"}
        for k, v in {**defaults, **s["petsc_options"]}.items():
            opts[f"{self.prefix}{k}"] = v
        ksp.setFromOptions()
        ksp.setTolerances(rtol=s["krylov_rtol"], atol=0.0, max_it=s["max_krylov"])
        if ksp.getType() != "preonly":
            ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
            ksp.getPC().setReusePreconditioner(False)
        if s["linear_solver"] == "gamg":
            self.A.setNearNullSpace(self._rigid_body_modes())
        self._ksp = ksp
        return ksp

    @property
    def factorization(self) -> str:
        """The factorisation in use: "single", "double", "petsc" (MUMPS), or "none" (GAMG)."""
        if self.settings["linear_solver"] != "mumps":
            return "none"
        return self._own_mode or "petsc"

    def _own_factorization(self) -> str | None:
        """"single"/"double" when the serial METIS LDL^T of :mod:`fem_sim.ldlt` is used, else
        None (PETSc's MUMPS or GAMG). Measured on the real liver (``bench/bench_solver.py``).
        """
        s = self.settings
        mode = s["factorization"]
        if mode not in ("auto", "single", "double", "petsc"):
            raise ValueError(f"settings.factorization: expected auto, single, double or petsc, "
                             f"got {mode!r}")
        if (s["linear_solver"] != "mumps" or s["lag_factorization"] or mode == "petsc"
                or self.comm.size > 1 or "pc_type" in s["petsc_options"]):
            if mode in ("single", "double") and self.comm.size > 1:
                raise ValueError(f"settings.factorization = {mode!r} runs on one process; "
                                 f"this problem has {self.comm.size} (use 'auto' or 'petsc')")
            return None
        if ldlt.load() is None:
            return None
        return "single" if mode == "auto" else mode

    def _back_solve(self) -> bool:
        """Set du = J^-1 rhs with the last factorisation (collective); False on failure.

        For chord steps and tangent predictors, which are approximate anyway: with float32
        factors this is one back-solve (relative error ~1e-3), not a refined solve.
        """
        if self._own_mode:
            if self._ldlt is None:
                return False
            self.du.array[:] = self._ldlt.solve(self.rhs.array_r)
            ok = bool(np.all(np.isfinite(self.du.array_r)))
        else:
            self._ksp.solve(self.rhs, self.du)
            ok = self._ksp.getConvergedReason() > 0
        if ok:
            self.du.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return ok

    def _rigid_body_modes(self):
        """The six rigid-body modes of the owned dofs, as GAMG's near-nullspace."""
        x = self.V.tabulate_dof_coordinates()[: self.n_owned]
        vecs = [self.b.duplicate() for _ in range(6)]
        for i in range(3):
            vecs[i].array.reshape(-1, 3)[:, i] = 1.0
        for k, (i, j) in enumerate(((0, 1), (1, 2), (2, 0))):
            a = vecs[3 + k].array.reshape(-1, 3)
            a[:, i] = -x[:, j]
            a[:, j] = x[:, i]
        for v in vecs:
            v.assemble()
        # Collective: orthonormalise for GAMG.
        for i, v in enumerate(vecs):
            for w in vecs[:i]:
                v.axpy(-v.dot(w), w)
            v.scale(1.0 / v.norm())
        return PETSc.NullSpace().create(vectors=vecs, comm=self.comm)

    def _solve_linear(self, stats: dict, eta: float | None = None) -> None:
        """Du = J^{-1} rhs to relative accuracy ``eta`` (collective). Raises StepFailure on
        linear-solver failure.
        """
        s = self.settings
        if self._own_mode:
            self._solve_own(stats, eta or s["krylov_rtol"])
            self._factorized = True
            return
        ksp = self._linear_solver()
        ksp.setTolerances(rtol=eta or s["krylov_rtol"], atol=0.0, max_it=s["max_krylov"])
        lagged = s["linear_solver"] == "mumps" and s["lag_factorization"]
        refactor = not lagged or self.Pmat is None or stats.pop("refactor_next", False)
        if lagged:
            if refactor:
                if self.Pmat is None:
                    self.Pmat = self.A.duplicate(copy=True)
                else:
                    self.A.copy(self.Pmat, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
                stats["factorizations"] += 1
            ksp.setOperators(self.A, self.Pmat)
        else:
            ksp.getPC().setReusePreconditioner(False)  # a new factorisation of this J
            ksp.setOperators(self.A, self.A)
            stats["factorizations"] += 1
        ksp.solve(self.rhs, self.du)
        its, reason = ksp.getIterationNumber(), ksp.getConvergedReason()
        stats["krylov"] += its
        if lagged and reason < 0 and not refactor:
            # The lagged factorisation is too far off: refactorise now and solve again.
            self.A.copy(self.Pmat, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            stats["factorizations"] += 1
            ksp.setOperators(self.A, self.Pmat)
            ksp.solve(self.rhs, self.du)
            its, reason = ksp.getIterationNumber(), ksp.getConvergedReason()
            stats["krylov"] += its
        if reason < 0:
            raise StepFailure(f"linear solver failed (PETSc KSP reason {reason} after {its} "
                              "iterations)")
        if lagged and its > s["refactor_after"]:
            stats["refactor_next"] = True
        self._factorized = True
        self.du.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def _solve_own(self, stats: dict, rtol: float) -> None:
        """Factorise J with :class:`fem_sim.ldlt.SerialLDLT` and solve to ``rtol`` (serial).

        If float32 factors cannot give the solve (GMRES does not reach ``rtol`` within
        ``max_krylov`` iterations, e.g. a tangent too ill-conditioned for single precision, or
        the float32 factorisation fails), the same matrix is factorised in float64 and the
        simulation goes on; ``stats["double_fallbacks"]`` counts these.
        """
        indptr, indices, values = self.jacobian_csr()
        precisions = [self._own_mode] + (["double"] if self._own_mode == "single" else [])
        why = ""
        for k, precision in enumerate(precisions):
            solver = self._ldlts.get(precision)
            if solver is None:
                solver = self._ldlts[precision] = ldlt.SerialLDLT(precision, bs=3)
            if k:
                stats["double_fallbacks"] = stats.get("double_fallbacks", 0) + 1
                log.debug("float32 LDL^T insufficient (%s); factorising in float64", why)
            try:
                solver.factor(indptr, indices, values)
            except ldlt.FactorError as exc:
                why = str(exc)
                continue
            stats["factorizations"] += 1
            x, its, ok = solver.solve_refined(ldlt.csr(indptr, indices, values),
                                              self.rhs.array_r, rtol, self.settings["max_krylov"])
            stats["krylov"] += its
            if ok:
                self._ldlt = solver
                self.du.array[:] = x
                self.du.ghostUpdate(addv=PETSc.InsertMode.INSERT,
                                    mode=PETSc.ScatterMode.FORWARD)
                return
            why = f"GMRES with the LDL^T factors did not reach {rtol:.1e} in {its} iterations"
        self._ldlt = None  # no valid factorisation: chord steps and tangents must not use one
        raise StepFailure(f"linear solver failed: {why}")

    # ------------------------------------------------------------------------------------------
    # Newton on one increment
    # ------------------------------------------------------------------------------------------
    def _constraint_gap(self, lam: float) -> float:
        """Set self.lift = prescribed - current at the constrained owned dofs; return max |gap|."""
        gap = lam * self._fixed_values_owned - self.u.x.array[self._fixed_owned]
        with self.lift.localForm() as loc:
            loc.set(0.0)
        self.lift.array[self._fixed_owned] = gap
        local = float(np.abs(gap).max()) if gap.size else 0.0
        return self.comm.allreduce(local, op=MPI.MAX)

    def _newton(self, lam: float, history: list[float], stats: dict) -> int:
        """Solve R(u; lam) = 0 from the current u (collective). Returns the number of Newton
        iterations (= factorisations) of this attempt; chord steps are counted in ``stats``.

        Each iteration is either a *chord step* (a back-solve with the last factorisation,
        kept while it contracts |R| by ``chord_contraction`` or better) or a full Newton step
        (fresh Jacobian, factorisation, line search). This is Shamanskii's modified Newton with
        an adaptive switch: the factorisation costs ~10 back-solves plus a residual, so a
        chord step that reduces |R| by 5x is cheaper than a Newton step, and the switch back
        to Newton as soon as contraction drops keeps the robustness of full Newton.
        """
        s = self.settings
        self._attempt_its = 0
        if not self._update_points(tangent=False):
            raise StepFailure(f"det F <= 0 at the predictor (min det F = {self.min_J:.3g})")
        r = self._residual(lam)
        if not np.isfinite(r):
            raise StepFailure("NaN/inf in the residual at the predictor")
        gap = self._constraint_gap(lam)
        scale = max(lam * self._f_norm, r)
        tol = max(s["atol"], s["rtol"] * scale)
        gap_tol = 1e-12 * max(1.0, self._value_norm * lam)
        history.append(r)
        u = self.u.vector
        # A chord step pays off only in Newton's fast phase: it contracts |R| about as much as
        # the last Newton step did, so it is tried after a Newton step that cut |R| by
        # ``chord_trigger`` or more, and kept up while each step contracts by
        # ``chord_contraction``. Measured on the real liver (15k nodes): chord steps straight
        # after the predictor or in Newton's slow phase derail the next Newton step.
        chord = False
        first = self._predicted_order <= 1
        it = n_chord = 0
        while True:
            self._attempt_its = it
            if r <= tol and gap <= gap_tol:
                return it
            if chord and gap <= gap_tol and n_chord < s["max_chord_steps"]:
                r_new = self._chord_step(lam, r)
                if r_new is not None:
                    n_chord += 1
                    stats["chord"] += 1
                    history.append(r_new)
                    chord = r_new <= s["chord_contraction"] * r
                    r = r_new
                    continue
                stats["chord_rejected"] += 1
                chord = False
            if it == s["max_iterations"]:
                break
            self._jacobian(lift=gap > 0)
            # Accurate linear solves keep Newton quadratic; measured: loose (Eisenstat-Walker)
            # tolerances cost more Newton iterations (assembly + kernels) than they save.
            eta = s["krylov_rtol"] if gap > 0 else min(
                1e-2, max(s["krylov_rtol"], 0.1 * tol / max(r, 1e-300)))
            self._solve_linear(stats, eta)
            u0 = u.copy()
            # Merit: the potential energy (Armijo along du, the natural merit function of
            # hyperelasticity: full Newton steps that first raise |R| are still taken), or |R|.
            energy0 = self._energy(lam)
            slope = self.b.dot(self.du)  # dPi/dalpha at alpha = 0 (free rows; b is R)
            alpha, accepted = 1.0, False
            for _ in range(8 if s["line_search"] else 1):
                u0.copy(u)
                u.axpy(alpha, self.du)
                ok = self._update_points(tangent=False)
                r_new = self._residual(lam) if ok else math.inf
                # The first full Newton step from a linear (Euler) prediction is kept unless it
                # is invalid (det F <= 0, NaN) or the residual explodes (> 1000x). Measured on
                # the real liver under a point load: that step raises |R| and the energy ~16x
                # and then converges quadratically; an Armijo test there costs 2-4 extra
                # iterations. After a higher-order prediction, and for later steps, |R| or the
                # energy must decrease (a kept 30x rise was measured to cost 8 iterations).
                if ok and (not s["line_search"] or gap > gap_tol or r_new <= tol
                           or (alpha == 1.0 and it == 0 and first and r_new <= 1e3 * r)
                           or r_new <= (1.0 - 1e-4 * alpha) * r
                           or (slope < 0 and self._energy(lam) <= energy0 + 1e-4 * alpha * slope)):
                    accepted = True
                    break
                alpha *= 0.5
            if not accepted and r <= 1e-10 * scale and gap <= gap_tol:
                # Round-off floor: |R| cannot decrease below ~eps * |F_int|; the state is
                # already converged far beyond any tolerance that matters. Keep it.
                u0.copy(u)
                self._update_points(tangent=False)
                self._residual(lam)
                u0.destroy()
                return it + 1
            u0.destroy()
            if not accepted:
                why = ("det F <= 0" if self.min_J <= 0 else
                       "NaN/inf in the residual" if not np.isfinite(r_new) else
                       "no residual decrease")
                raise StepFailure(f"line search failed at load {lam:.4g}: {why} "
                                  f"(|R| = {r:.3e})")
            it += 1
            chord = self._chord_allowed() and alpha == 1.0 and r_new <= s["chord_trigger"] * r
            r = r_new
            gap = self._constraint_gap(lam)
            history.append(r)
            if it >= 7 and r > history[0]:
                raise StepFailure(f"Newton is not converging at load {lam:.4g} (|R| = {r:.3e} "
                                  f"after {it} iterations, {history[0]:.3e} at the start)")
        raise StepFailure(f"Newton did not converge in {s['max_iterations']} iterations at load "
                          f"{lam:.4g} (|R| = {r:.3e}, tolerance {tol:.1e})")

    def _chord_allowed(self) -> bool:
        s = self.settings
        return (s["chord_contraction"] > 0 and s["linear_solver"] == "mumps"
                and not s["lag_factorization"])

    def _chord_step(self, lam: float, r: float) -> float | None:
        """One chord step, u += J_old^-1 (-R): a back-solve with the last factorisation.

        Returns the new |R| if it contracted by ``chord_contraction``; otherwise restores the
        state (u, stresses, residual) and returns None. Collective.
        """
        saved = (self.u.x.array.copy(), self.P_q.x.array.copy(), self.W_q.x.array.copy(),
                 self.b.array.copy(), self._tangent_fresh, self.min_J)
        self.b.copy(self.rhs)
        self.rhs.scale(-1.0)
        r_new = math.inf
        if self._back_solve():  # the operator is unchanged: no refactorisation
            self.u.vector.axpy(1.0, self.du)
            if self._update_points(tangent=False):
                r_new = self._residual(lam)
        if r_new <= self.settings["chord_contraction"] * r:
            return r_new
        u_arr, P_arr, W_arr, b_arr, self._tangent_fresh, self.min_J = saved
        self.u.x.array[:] = u_arr
        self.P_q.x.array[:] = P_arr
        self.W_q.x.array[:] = W_arr
        self.b.array[:] = b_arr
        return None

    # ------------------------------------------------------------------------------------------
    # Boundary conditions and loads
    # ------------------------------------------------------------------------------------------
    def _set_constraints(self, constraints: list[Constraint]) -> None:
        """Map node constraints to local dofs. For P2, an edge dof is constrained (to the mean
        of its ends' values: the P1 interpolant) when both ends are, in that component.
        """
        local, values = [], []
        by_node: dict[tuple[int, int], float] = {}
        for c in constraints:
            nodes = np.atleast_1d(np.asarray(c.nodes, dtype=np.int64))
            if nodes.size and (nodes.min() < 0 or nodes.max() >= self.n_nodes):
                raise ValueError(f"Constraint: node ids outside [0, {self.n_nodes})")
            vals = np.broadcast_to(np.asarray(c.values, dtype=np.float64),
                                   (nodes.size, len(c.components)))
            for n, row in zip(nodes.tolist(), vals):
                for comp, val in zip(c.components, row):
                    by_node[(n, comp)] = float(val)
        for (n, comp), val in by_node.items():
            blk = self.src_to_block.get(n)
            if blk is not None:
                local.append(3 * blk + comp)
                values.append(val)
        if self.degree == 2:
            for blk, a, b in zip(*[x.tolist() for x in dc.edge_dof_source_ids(self.mesh, self.V)]):
                for comp in range(3):
                    va, vb = by_node.get((a, comp)), by_node.get((b, comp))
                    if va is not None and vb is not None:
                        local.append(3 * blk + comp)
                        values.append(0.5 * (va + vb))
        local = np.asarray(local, dtype=np.int32)
        values = np.asarray(values, dtype=np.float64)
        local, first = np.unique(local, return_index=True)
        self._fixed_local, self._fixed_values = local, values[first]
        owned = local < 3 * self.n_owned
        self._fixed_owned = local[owned]
        self._fixed_values_owned = self._fixed_values[owned]
        self._value_norm = self.comm.allreduce(
            float(np.abs(self._fixed_values).max()) if values.size else 0.0, op=MPI.MAX)
        blocks = dc.global_block_indices(self.V, self._fixed_owned // 3)
        self._fixed_global = (3 * blocks + self._fixed_owned % 3).astype(np.int32)
        n_fixed = self.comm.allreduce(int(owned.sum()), op=MPI.SUM)
        if n_fixed == 0:
            raise ValueError("OgdenProblem.solve: no constrained degree of freedom (the body "
                             "could move rigidly); give at least one Constraint")

    def _set_loads(self, loads: list) -> None:
        """f_ext at load fraction 1 from nodal and patch loads (collective)."""
        with self.f_ext.localForm() as loc:
            loc.set(0.0)
        for ld in loads:
            if isinstance(ld, PatchLoad):
                dc.interpolate(self.w, ld.weight)
                area = dc.assemble_scalar(self.patch_area, self.comm)
                if not area > 0:
                    raise ValueError(f"PatchLoad at {ld.centre} (radius {ld.radius} mm) covers "
                                     "no boundary")
                self.t.value[:] = ld.force / area
                tmp = self.b.duplicate()
                dc.assemble_vector(tmp, self.L_patch)
                self.f_ext.axpy(1.0, tmp)
                tmp.destroy()
        arr = self.f_ext.array
        for ld in loads:
            if isinstance(ld, PatchLoad):
                continue
            bad = (ld.nodes < 0) | (ld.nodes >= self.n_nodes)
            if bad.any():
                raise ValueError(f"NodalLoad: node ids {ld.nodes[bad][:5].tolist()} outside "
                                 f"[0, {self.n_nodes})")
            for n, f in zip(ld.nodes.tolist(), ld.forces):
                blk = self.src_to_block.get(n)
                if blk is not None and blk < self.n_owned:
                    arr[3 * blk: 3 * blk + 3] += f
        self._f_norm = self.f_ext.norm()

    # ------------------------------------------------------------------------------------------
    # Gathering results in source-node order
    # ------------------------------------------------------------------------------------------
    def gather_vertex_values(self, arr_blocked: np.ndarray) -> np.ndarray | None:
        """Values (n_local_blocks, 3) at owned vertex dofs -> (n_nodes, 3) on rank 0.

        Collective.
        """
        vals = arr_blocked[self.owned_vertex_blocks]
        parts = self.comm.gather((self.owned_vertex_src, vals), root=0)
        if self.comm.rank != 0:
            return None
        out = np.full((self.n_nodes, 3), np.nan)
        for src, v in parts:
            out[src] = v
        return out

    def displacement(self) -> np.ndarray | None:
        """Current displacement at the mesh nodes, source order, on rank 0 (collective)."""
        return self.gather_vertex_values(self.u.x.array.reshape(-1, 3))

    def reaction(self, nodes) -> np.ndarray:
        """Total internal force (N, 3 components) on the dofs of a node set: the reaction
        force when the set is constrained (collective; same value on every rank).

        Vertex dofs of the nodes count; for P2 also edge dofs whose two ends are in the set.
        """
        self._update_points(tangent=False)
        dc.assemble_vector(self.b, self.L)
        fint = self.b.array.reshape(-1, 3)
        members = set(np.asarray(nodes, dtype=np.int64).tolist())
        blocks = [b for b, n in zip(self.owned_vertex_blocks.tolist(),
                                    self.owned_vertex_src.tolist()) if n in members]
        if self.degree == 2:
            eb, ea, ee = dc.edge_dof_source_ids(self.mesh, self.V)
            blocks += [b for b, x, y in zip(eb.tolist(), ea.tolist(), ee.tolist())
                       if b < self.n_owned and x in members and y in members]
        local = fint[np.asarray(blocks, dtype=np.int64)].sum(axis=0) if blocks else np.zeros(3)
        return self.comm.allreduce(local, op=MPI.SUM)

    # ------------------------------------------------------------------------------------------
    # One simulation
    # ------------------------------------------------------------------------------------------
    def solve(self, material: OgdenMaterial, constraints: list[Constraint],
              loads: list[NodalLoad], fractions) -> Solution:
        """Run the load steps of one simulation from the undeformed state (collective)."""
        s = self.settings
        fractions = np.asarray(fractions, dtype=np.float64)
        if fractions.size == 0 or np.any(np.diff(fractions) <= 0) or fractions[0] <= 0:
            raise ValueError(f"fractions must be increasing and > 0, got {fractions}")
        self.material = material
        self._set_constraints(constraints)
        self._set_loads(loads)
        self.u.x.array[:] = 0.0
        self.Pmat = None  # a new material: the old factorisation is no preconditioner for it
        self._ldlt = None
        sol = Solution(fractions=fractions, displacement=None)
        stored = []
        states: list[tuple[float, np.ndarray]] = [(0.0, self.u.x.array.copy())]
        lam, dlam = 0.0, float(fractions[0])
        stats = {"factorizations": 0, "krylov": 0, "chord": 0, "chord_rejected": 0}
        self._factorized = False  # no factorisation of this simulation's Jacobian yet
        self._tangents: list[tuple[float, np.ndarray]] = []  # (load, du/dload) for predictors
        self._hermite: list[tuple[float, np.ndarray, np.ndarray]] = []  # (load, u, du/dload)
        if self._hermite_on():
            self._record_tangent(0.0, stats)
        for target in fractions:
            t0 = time.perf_counter()
            iters, cutbacks, history, retry_plain = 0, 0, [], False
            dlam = min(dlam, target - lam) if dlam > 0 else target - lam
            try:
                while lam < target - 1e-14:
                    trial = min(lam + dlam, target)
                    if target - trial < 1e-3 * dlam:
                        trial = target
                    self._predict(states, trial, extrapolate=not retry_plain)
                    try:
                        its = self._newton(trial, history, stats)
                    except StepFailure as exc:
                        iters += self._attempt_its  # failed attempts cost iterations too
                        if not retry_plain and len(states) > 1 and \
                                self.settings["predictor"] != "previous":
                            # An extrapolated start can lie outside Newton's basin: retry the
                            # same increment from the last converged state before cutting back.
                            retry_plain = True
                            self.u.x.array[:] = states[-1][1]
                            continue
                        retry_plain = False
                        cutbacks += 1
                        log.debug("step to %.4g failed (%s); cut back", trial, exc)
                        if cutbacks > s["max_cutbacks"]:
                            raise StepFailure(f"{exc}; gave up after {s['max_cutbacks']} "
                                              "cut-backs") from None
                        self.u.x.array[:] = states[-1][1]
                        dlam = 0.5 * (trial - lam)
                        stats["refactor_next"] = True
                        continue
                    iters += its
                    if its == 0:
                        # Converged on chord steps alone: the factorisation is from an older
                        # state, so the next tangent would not belong to this one; do not mix
                        # it into a higher-order predictor.
                        self._tangents = []
                    retry_plain = False
                    lam = trial
                    states = (states + [(lam, self.u.x.array.copy())])[-3:]
                    if self._hermite_on():
                        self._record_tangent(lam, stats)
                    if its <= 3 and cutbacks:
                        dlam *= 2.0  # easy step after a cut-back: let the increment grow
            except StepFailure as exc:
                sol.status, sol.failure_reason = "failed", str(exc)
                self.u.x.array[:] = states[-1][1]
                break
            sol.newton_iterations.append(iters)
            sol.residual_norms.append(history[-1])
            sol.residual_history.append(history)
            sol.cutbacks.append(cutbacks)
            sol.wall_time.append(time.perf_counter() - t0)
            stored.append(self.displacement())
            dlam = max(dlam, 0.0)
            nxt = np.searchsorted(fractions, target, side="right")
            if nxt < fractions.size and not cutbacks:
                dlam = fractions[nxt] - target
        sol.factorizations, sol.krylov_iterations = stats["factorizations"], stats["krylov"]
        sol.chord_steps = stats["chord"]
        sol.chord_rejected = stats["chord_rejected"]
        sol.double_fallbacks = stats.get("double_fallbacks", 0)
        if self.comm.rank == 0:
            sol.displacement = (np.stack(stored) if stored
                                else np.zeros((0, self.n_nodes, 3)))
        return sol

    def _hermite_on(self) -> bool:
        """The Hermite predictor needs cheap tangents at converged states: GMRES with the last
        factorisation, from fem_sim.ldlt or from PETSc's MUMPS with the preconditioner kept
        (``bench/bench_predictor.py``, 3k-node phantom, two ranks: 11.5 factorisations per
        simulation instead of 13.9 with "tangent"). With GAMG, a lagged factorisation or a
        user KSP it means "tangent"; with prescribed displacements, "extrapolate".
        """
        s = self.settings
        return (s["predictor"] == "hermite" and self._value_norm == 0.0
                and s["linear_solver"] == "mumps" and not s["lag_factorization"]
                and (self._own_mode is not None or "ksp_type" not in s["petsc_options"]))

    def _record_tangent(self, lam: float, stats: dict) -> None:
        """du/dlam = J(u)^-1 f_ext at the converged state u (collective), kept with u for the
        Hermite predictor. J is assembled at u; the solve is GMRES preconditioned with the last
        factorisation (a Newton iterate close to u), or a new factorisation if that fails.
        """
        self._update_points(tangent=True)
        self._jacobian(lift=False)
        self.rhs.array[:] = self.f_ext.array_r
        self.rhs.array[self._fixed_owned] = 0.0
        n = self.rhs.array_r.size
        done = False
        if self._ldlt is not None:  # the factors of an older Jacobian precondition this one
            x, its, done = self._ldlt.solve_refined(ldlt.csr(*self.jacobian_csr()),
                                                    self.rhs.array_r, TANGENT_RTOL,
                                                    TANGENT_MAX_GMRES)
            stats["krylov"] += its
            if done:
                self.du.array[:] = x
        elif not self._own_mode and self._factorized:
            done = self._petsc_stale_solve(stats)
        if not done:
            try:
                self._solve_linear(stats, TANGENT_RTOL)
            except StepFailure as exc:  # e.g. a singular tangent: predict without tangents
                log.debug("no tangent at load %.4g (%s)", lam, exc)
                self._hermite = []
                return
        t = self.du.array_r[:n].copy()
        self._hermite = (self._hermite + [(lam, self.u.x.array[:n].copy(), t)])[
            -self.settings["predictor_order"]:]

    def _petsc_stale_solve(self, stats: dict) -> bool:
        """PETSc's path (collective): du = J^-1 rhs by GMRES preconditioned with the last
        MUMPS factorisation, kept (``PCSetReusePreconditioner``) although J changed. The
        reuse flag stays on, so back-solves keep using that factorisation until
        :meth:`_solve_linear` asks for a new one.
        """
        ksp = self._linear_solver()
        ksp.getPC().setReusePreconditioner(True)
        ksp.setType(PETSc.KSP.Type.GMRES)
        ksp.setPCSide(PETSc.PC.Side.RIGHT)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.setTolerances(rtol=TANGENT_RTOL, atol=0.0, max_it=TANGENT_MAX_GMRES)
        ksp.setOperators(self.A, self.A)
        try:
            ksp.solve(self.rhs, self.du)
            its, ok = ksp.getIterationNumber(), ksp.getConvergedReason() > 0
        finally:
            ksp.setType(PETSc.KSP.Type.PREONLY)
        stats["krylov"] += its
        if ok:
            self.du.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return ok

    def _predict_hermite(self, lam: float) -> None:
        """Set u(lam) from the Hermite polynomial through the last converged states and their
        tangents (degree 2m-1 for m points; collective).
        """
        pts = self._hermite
        lam0 = pts[-1][0]
        h = max(lam - lam0, 1e-300)
        m = len(pts)
        deg = 2 * m - 1
        M = np.zeros((2 * m, deg + 1))
        p = np.arange(deg + 1)
        for i, (li, _, _) in enumerate(pts):
            t = (li - lam0) / h
            M[2 * i] = t ** p
            M[2 * i + 1] = np.where(p > 0, p * t ** np.maximum(p - 1, 0), 0.0) / h
        w = np.linalg.solve(M.T, np.ones(deg + 1))  # evaluate at t = 1
        arr = self.u.x.array
        n = pts[-1][1].size
        arr[:n] = sum(w[2 * i] * ui + w[2 * i + 1] * ti for i, (_, ui, ti) in enumerate(pts))
        dc.scatter_forward(self.u)
        self._predicted_order = m

    def _predict(self, states: list[tuple[float, np.ndarray]], lam: float,
                 extrapolate: bool = True) -> None:
        """Initial guess for load ``lam`` (collective).

        "tangent": u_last + (lam - lam_last) J^-1 f_ext, one back-solve with the last
        factorisation (measured on the real liver: 42 instead of 48 Newton iterations per
        simulation with extrapolation, which overshoots in the stiffening early steps);
        "extrapolate": Lagrange extrapolation through the last converged states (up to
        quadratic), also used when displacements are prescribed; "previous": the last state.
        """
        mode = self.settings["predictor"]
        self._predicted_order = 0
        if extrapolate and self._hermite_on() and self._hermite:
            self._predict_hermite(lam)
            return
        if not extrapolate or mode == "previous" or len(states) == 1:
            self.u.x.array[:] = states[-1][1]
            return
        if mode in ("tangent", "hermite") and self._factorized and self._value_norm == 0.0:
            lam0, u0 = states[-1]
            self.rhs.array[:] = self.f_ext.array
            self.rhs.array[self._fixed_owned] = 0.0
            if self._back_solve():
                # du/dlam at lam0 = J^-1 f_ext (J from the last Newton iteration). Keep the
                # last few; u(lam) = u0 + integral over [lam0, lam] of the polynomial through
                # them (order 1: Euler; 2, 3: the tangent's own change is extrapolated too).
                v = self.du.array_r.copy()
                tangents = [t for t in self._tangents if t[0] < lam0] + [(lam0, v)]
                self._tangents = tangents[-self.settings["predictor_order"]:]
                self._predicted_order = len(self._tangents)
                nodes = np.array([t[0] - lam0 for t in self._tangents])
                d = lam - lam0
                k = np.arange(nodes.size)
                V = nodes[None, :] ** k[:, None]  # V[k, i] = s_i^k
                w = np.linalg.solve(V, d ** (k + 1) / (k + 1))
                arr = self.u.x.array
                arr[:] = u0
                n_owned = v.size
                for wi, (_, vi) in zip(w, self._tangents):
                    arr[:n_owned] += wi * vi
                dc.scatter_forward(self.u)
                return
        lams = [st[0] for st in states]
        guess = np.zeros_like(states[-1][1])
        for i, (li, ui) in enumerate(states):
            w = 1.0
            for j, lj in enumerate(lams):
                if j != i:
                    w *= (lam - lj) / (li - lj)
            guess += w * ui
        self.u.x.array[:] = guess
