"""Linear solvers for the Newton systems J du = rhs.

One interface, :class:`LinearSolver`:

* ``solve(J, rhs, du, rtol)``: factorise J (or precondition) and solve to ``rtol``; raises
  :class:`StepFailure` when it cannot;
* ``back_solve(rhs, du)``: one solve with the last factorisation (chord steps, predictors);
* ``solve_near(J, rhs, du, rtol, maxit)``: GMRES on J preconditioned with the last
  factorisation of a nearby matrix, no new factorisation (the Hermite predictor's tangents);
* ``invalidate()``: the next ``solve`` must factorise afresh (after a cut-back).

Each solver counts its own work in ``counts`` (:class:`LinearCounts`), reset per simulation.

Implementations: :class:`SerialLDLTSolver` (MKL PARDISO's Cholesky, :mod:`fem_sim.solver.pardiso`,
or MUMPS' LDL^T through its C interface, :mod:`fem_sim.solver.ldlt`, with METIS ordering,
float32 factors refined by GMRES; one process; it exists because Debian's MUMPS has no METIS
and PETSc 3.18 gives a user ordering only to LU) and
:class:`PetscSolver` (PETSc KSP: MUMPS' Cholesky, or CG + GAMG with the rigid-body
near-nullspace; any number of processes). :func:`make_linear_solver` picks one from the
settings, through the one rule table :mod:`data_spec.solver_rules`.
"""

from __future__ import annotations

import logging

import numpy as np
from petsc4py import PETSc

from data_spec import solver_rules
from fem_sim.solver import blas, ldlt, pardiso, tet
from fem_sim.solver.assembly import Jacobian
from fem_sim.solver.results import LinearCounts, StepFailure
from fem_sim.solver.settings import SolverSettings

log = logging.getLogger(__name__)
# Krylov iterations per solve when settings.max_krylov is 0: GMRES refining a float32
# factorisation converges in a few (60 means the factors are poor: fall back), CG + GAMG needs
# hundreds at K/mu = 200 (about 120 per solve on tiny_scene1, 240 on scene 1's P2 mesh).
REFINE_MAX_IT = 60
REFINE_BLOCK_IT = 6   # block iterative-refinement sweeps before a row gets its own GMRES
BLOCK_CONTRACTION = 0.1   # a sweep that shrinks a row's residual less: the row to GMRES
BLOCK_ROWS = 256   # rows of a block's residual computed at once (its temporaries stay small)
PROBES = 8   # random combinations of a block's rows that vouch for all of them at once
GAMG_MAX_IT = 1000
_warned_unused: set[tuple[str, ...]] = set()  # unused options warned about, once per process
Factors = ldlt.SerialLDLT | pardiso.PardisoCholesky  # one interface: factor, solve, ...


_petsc_lib = None


def _option_used(name: str) -> bool:
    """Whether PETSc read option ``name`` (no leading dash; PetscOptionsUsed on the global
    database, through the libpetsc this process loaded); True when that cannot be asked.
    """
    global _petsc_lib
    import ctypes

    if _petsc_lib is None:
        _petsc_lib = False
        try:
            with open("/proc/self/maps") as fh:
                paths = {ln.split()[-1] for ln in fh if "libpetsc" in ln and ".so" in ln}
            for path in sorted(paths):
                lib = ctypes.CDLL(path)
                if hasattr(lib, "PetscOptionsUsed"):
                    _petsc_lib = lib
                    break
        except OSError:
            pass
    if not _petsc_lib:
        return True
    used = ctypes.c_int(0)
    err = _petsc_lib.PetscOptionsUsed(None, name.encode(), ctypes.byref(used))
    return err != 0 or bool(used.value)


def _ghost_update(vec) -> None:
    vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)


class LinearSolver:
    """Interface (see the module docstring)."""

    name = "none"
    csr = False          # takes CSR arrays (one process) rather than a PETSc matrix
    direct = False       # back-solves with a kept factorisation are cheap (chord steps)
    solves_near = False  # solve_near is available (Hermite tangents)

    def __init__(self, settings: SolverSettings):
        self.settings = settings
        self.counts = LinearCounts()

    def reset(self) -> None:
        """A new simulation: no factorisation of its Jacobians exists yet; counts from zero."""
        self.counts = LinearCounts()

    @property
    def has_factorization(self) -> bool:
        raise NotImplementedError

    def solve(self, J: Jacobian, rhs, du, rtol: float) -> None:
        raise NotImplementedError

    def back_solve(self, rhs, du) -> bool:
        raise NotImplementedError

    def solve_near(self, J: Jacobian, rhs, du, rtol: float, maxit: int) -> bool:
        return False

    def solve_recurring(self, J: Jacobian, rhs, du, rtol: float) -> None:
        """As :meth:`solve`, for a matrix that recurs in every simulation of a problem (the
        tangent at u = 0 of the same mesh, material and constraints): a solver may keep its
        factorisation and reuse it when the same matrix comes again. Default: :meth:`solve`.
        """
        self.solve(J, rhs, du, rtol)

    def solve_recurring_block(self, J: Jacobian, rhs, du, B: np.ndarray,
                              rtol: float) -> np.ndarray:
        """X (k, n_owned) with J X[i] = B[i] (owned rows) each to ``rtol``, for the recurring
        matrix of :meth:`solve_recurring`; ``rhs`` and ``du`` are work vectors. Default: one
        refined solve per row (collective, every rank the same k).
        """
        out = np.empty_like(B)
        for i, b in enumerate(B):
            rhs.array[:] = b
            self.solve_recurring(J, rhs, du, rtol)
            out[i] = du.array_r
        return out

    def invalidate(self) -> None:
        pass


def block_residual(A, B: np.ndarray, X: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """B[rows] - (A X[rows]^T)^T, BLOCK_ROWS rows at a time: a block of thousands of rows of
    a liver's size in one product makes temporaries of the size of B (a gigabyte for the
    unit responses at every surface node) where a chunk's are a few megabytes.
    """
    R = np.empty((rows.size, B.shape[1]))
    for s in range(0, rows.size, BLOCK_ROWS):
        r = rows[s:s + BLOCK_ROWS]
        R[s:s + r.size] = B[r] - (A @ X[r].T).T
    return R


def row_norms(M: np.ndarray) -> np.ndarray:
    """|row| of each row of ``M``, without a temporary of its size."""
    return np.sqrt(np.einsum("ij,ij->i", M, M))


def rows_surely_within(A, B: np.ndarray, X: np.ndarray, size: np.ndarray, rtol: float,
                       seed: int = 0) -> bool:
    """Whether every row of the block solve A X^T = B^T is within ``rtol`` of its right-hand
    side (|b_i - A x_i| <= rtol |b_i|), from PROBES random combinations of its rows instead
    of the whole residual: with weights g_ki / |b_i| (g standard normal), the combined
    residual's squared norm has mean sum_i rel_i^2 whatever the rows, so a mean over the
    probes under (rtol / 10)^2 puts every rel_i under rtol unless a chi-square of PROBES
    degrees of freedom fell below a hundredth of its mean (probability about 1e-7 for 8).
    False: the caller checks row by row.
    """
    W = np.random.default_rng(seed).standard_normal((PROBES, len(B))) / size
    R = W @ B - (A @ (W @ X).T).T
    return bool(np.mean(row_norms(R) ** 2) <= (0.1 * rtol) ** 2)


def _is_kept(kept: tuple | None, indices: np.ndarray, values: np.ndarray) -> bool:
    """Whether ``kept`` (column indices, values, factors) holds this matrix, entry by entry."""
    return kept is not None and np.array_equal(kept[1], values) \
        and np.array_equal(kept[0], indices)

class SerialLDLTSolver(LinearSolver):
    """Float32 Cholesky by MKL PARDISO ("pardiso"), or MUMPS LDL^T in float32 ("single") or
    float64 ("double"), all with METIS ordering.

    A matrix that is not positive definite fails the Cholesky factorisation and is factorised
    by MUMPS' float32 LDL^T instead (``counts.cholesky_fallbacks``, which also counts the rare
    Cholesky whose factors GMRES could not refine to ``rtol``). If float32 factors cannot
    give the solve (GMRES does not reach ``rtol`` within ``max_krylov`` iterations, e.g. a
    tangent too ill-conditioned for single precision, or the float32 factorisation fails), the
    same matrix is factorised in float64 and the simulation goes on;
    ``counts.double_fallbacks`` counts these.
    """

    # the factorisations a mode tries, in order
    CHAINS = {"pardiso": ("pardiso", "single", "double"), "single": ("single", "double"),
              "double": ("double",)}

    csr = direct = solves_near = True

    def __init__(self, settings: SolverSettings, precision: str):
        super().__init__(settings)
        self.name = precision
        if settings.petsc_options:  # the rule table allows no pc_type here, so none is read
            log.warning("petsc_options %s: have no effect, the serial factorisation %r runs "
                        "(PETSc's solvers run with factorization = 'petsc' or linear_solver "
                        "= 'gamg')", sorted(settings.petsc_options), precision)
        # by (slot, precision); each keeps its analysis. Slot "work" holds Newton's
        # factorisations, slot "recurring" the one of solve_recurring, kept across simulations.
        self._ldlts: dict[tuple[str, str], Factors] = {}
        self._ldlt: Factors | None = None     # the one holding the last factorisation
        # (column indices, values, factors) of the recurring matrix's last factorisation
        self._recurring: tuple[np.ndarray, np.ndarray, Factors] | None = None
        self._block: tuple[np.ndarray, np.ndarray, Factors] | None = None  # its float64 one

    def reset(self) -> None:
        super().reset()
        self._ldlt = None

    @property
    def has_factorization(self) -> bool:
        return self._ldlt is not None

    def solve(self, J: Jacobian, rhs, du, rtol: float, slot: str = "work") -> None:
        indptr, indices, values = J.csr()
        why = ""
        for k, precision in enumerate(self.CHAINS[self.name]):
            solver = self._ldlts.get((slot, precision))
            if solver is None:
                # Unpivoted float32 factors unless asked (the float64 fallback pivots).
                solver = self._ldlts[slot, precision] = (
                    pardiso.PardisoCholesky() if precision == "pardiso" else
                    ldlt.SerialLDLT(precision, bs=3,
                                    pivoting=precision == "double" or self.settings.pivoting))
                for (_, p), other in self._ldlts.items():  # one METIS ordering per pattern
                    if other is not solver and p == precision:
                        solver.share_ordering(other)
            if precision == "double" and k:
                self.counts.double_fallbacks += 1
                log.debug("float32 factors insufficient (%s); factorising in float64", why)
            elif k:
                self.counts.cholesky_fallbacks += 1
                log.debug("Cholesky insufficient (%s); factorising with MUMPS' LDL^T", why)
            try:
                solver.factor(indptr, indices, values)
            except ldlt.FactorError as exc:
                why = str(exc)
                continue
            self.counts.factorizations += 1
            ok, its = self._refine(solver, J, rhs, du, rtol,
                                   self.settings.max_krylov or REFINE_MAX_IT)
            if ok:
                return
            why = f"GMRES with the LDL^T factors did not reach {rtol:.1e} in {its} iterations"
        self._ldlt = None  # no valid factorisation: chord steps and tangents must not use one
        raise StepFailure(f"linear solver failed: {why}")

    def solve_recurring(self, J: Jacobian, rhs, du, rtol: float) -> None:
        """The factorisation of the recurring matrix is kept in its own slot (Newton's
        factorisations do not overwrite it) with a copy of the matrix; when the same matrix
        (equal values, entry by entry) comes again, the solve reuses it: a batch of
        simulations on one liver and material saves one factorisation per simulation. The
        solution is the same as with a fresh factorisation (the same factors: MUMPS, and
        PARDISO on one thread, are deterministic for equal input and the same analysis;
        tested; PARDISO on several threads may differ from a fresh one in the last bits).
        """
        _, indices, values = J.csr()
        kept = self._recurring
        if _is_kept(kept, indices, values) \
                and self._refine(kept[2], J, rhs, du, rtol,
                                 self.settings.max_krylov or REFINE_MAX_IT)[0]:
            self.counts.reused_factorizations += 1
            return
        self._recurring = None
        self.solve(J, rhs, du, rtol, slot="recurring")
        self._recurring = (indices.copy(), values.copy(), self._ldlt)

    def solve_recurring_block(self, J: Jacobian, rhs, du, B: np.ndarray,
                              rtol: float) -> np.ndarray:
        """As the base class's, with a float64 factorisation of the matrix (PARDISO's, or
        MUMPS' LDL^T without MKL), made once and kept while the same matrix comes again: the
        rows back-solved at once, then the residuals of the rows not yet within ``rtol`` and
        their corrections, again at once. Float32 factors of a nearly incompressible tangent
        contract a residual only 3-10 times a sweep (float32 eps times its condition number),
        so a block of thousands of rows costs fewer back-solves with float64 factors at twice
        the price each. A row whose residual shrinks less than BLOCK_CONTRACTION in a sweep,
        or that is still above ``rtol`` after REFINE_BLOCK_IT sweeps, gets its own GMRES solve.
        """
        if not len(B):
            return np.zeros_like(B)
        factors = self._block_factors(J)
        A = ldlt.csr(*J.csr())
        X = factors.solve_block(B)
        self.counts.back_solves += len(B)
        size = np.maximum(row_norms(B), 1e-300)
        if rows_surely_within(A, B, X, size, rtol):   # the usual float64 case, at once
            return X
        todo, last = np.arange(len(B)), np.full(len(B), np.inf)
        R = block_residual(A, B, X, todo)
        for sweep in range(REFINE_BLOCK_IT + 1):
            rel = row_norms(R) / size[todo]
            going = (rel > rtol) & (rel < BLOCK_CONTRACTION * last[todo])
            stalled = todo[(rel > rtol) & ~going]
            last[todo] = rel
            todo = todo[going]
            if sweep == REFINE_BLOCK_IT:
                stalled = np.concatenate([stalled, todo])
            self._gmres_rows(J, rhs, du, B, X, stalled, rtol)
            if not todo.size or sweep == REFINE_BLOCK_IT:
                return X
            X[todo] += factors.solve_block(R[going])
            self.counts.back_solves += todo.size
            R = block_residual(A, B, X, todo)
        return X

    def _block_factors(self, J: Jacobian) -> Factors:
        """The float64 factors of J for :meth:`solve_recurring_block`, kept with a copy of
        the matrix and reused while its values are the same.
        """
        indptr, indices, values = J.csr()
        kept = self._block
        if _is_kept(kept, indices, values):
            self.counts.reused_factorizations += 1
            return kept[2]
        self._block = None
        kinds = (["pardiso64"] if self.name == "pardiso" else []) + ["double"]
        for kind in kinds:
            solver = self._ldlts.get(("block", kind))
            if solver is None:
                solver = self._ldlts["block", kind] = (
                    pardiso.PardisoCholesky(double=True) if kind == "pardiso64" else
                    ldlt.SerialLDLT("double", bs=3, pivoting=True))
            try:
                solver.factor(indptr, indices, values)
            except ldlt.FactorError as exc:
                log.debug("float64 %s factorisation failed (%s)", kind, exc)
                continue
            self.counts.factorizations += 1
            self._block = (indices.copy(), values.copy(), solver)
            return solver
        raise StepFailure("linear solver failed: no float64 factorisation of the block's "
                          "matrix")

    def _gmres_rows(self, J: Jacobian, rhs, du, B: np.ndarray, X: np.ndarray,
                    rows: np.ndarray, rtol: float) -> None:
        """X[i] by its own refined solve, for each of ``rows``."""
        for i in rows.tolist():
            rhs.array[:] = B[i]
            self.solve_recurring(J, rhs, du, rtol)
            X[i] = du.array_r

    def back_solve(self, rhs, du) -> bool:
        """One back-solve: with float32 factors the relative error is ~1e-3, fine for chord
        steps and predictors, which are approximate anyway.
        """
        if self._ldlt is None:
            return False
        self.counts.back_solves += 1
        du.array[:] = self._ldlt.solve(rhs.array_r)
        ok = bool(np.all(np.isfinite(du.array_r)))
        if ok:
            _ghost_update(du)
        return ok

    def solve_near(self, J: Jacobian, rhs, du, rtol: float, maxit: int) -> bool:
        if self._ldlt is None:
            return False
        return self._refine(self._ldlt, J, rhs, du, rtol, maxit)[0]

    def _refine(self, solver: Factors, J: Jacobian, rhs, du, rtol: float,
                maxit: int) -> tuple[bool, int]:
        """GMRES on J preconditioned with ``solver``'s factors; if it reaches ``rtol``, du is
        the solution and ``solver`` holds the last factorisation. Returns (converged,
        iterations).
        """
        x, its, ok = solver.solve_refined(tet.operator(*J.csr()), rhs.array_r, rtol, maxit)
        self.counts.krylov_iterations += its
        if ok:
            self._ldlt = solver
            du.array[:] = x
            _ghost_update(du)
        return ok, its


class PetscSolver(LinearSolver):
    """PETSc's KSP on the assembled PETSc matrix: MUMPS' Cholesky ("petsc") or CG + GAMG
    ("gamg"); any KSP/PC from ``petsc_options`` (an option PETSc never reads is reported).
    Collective on the matrix's communicator.
    """

    def __init__(self, settings: SolverSettings, comm, prefix: str,
                 coordinates: np.ndarray | None = None):
        super().__init__(settings)
        self.comm, self.prefix = comm, prefix
        self.coordinates = coordinates  # of the owned dof blocks: GAMG's rigid-body modes
        s = settings
        self.name = "none" if s.linear_solver == "gamg" else "petsc"
        self.direct = s.linear_solver == "direct"
        self.solves_near = self.direct and "ksp_type" not in s.petsc_options
        self._ksp = None
        self._factorized = False
        self.unused_options: list[str] = []  # petsc_options PETSc never read (after a solve)

    def reset(self) -> None:
        super().reset()
        self._factorized = False

    @property
    def max_it(self) -> int:
        """Krylov iterations per solve from the settings (0: the path's own limit)."""
        gamg = self.settings.linear_solver == "gamg"
        return self.settings.max_krylov or (GAMG_MAX_IT if gamg else REFINE_MAX_IT)

    def _set_tolerances(self, ksp, rtol: float) -> None:
        """The Newton loop's ``rtol`` and the settings' limit, except where the user's
        petsc_options set a KSP tolerance: that one stays as PETSc read it.
        """
        user = self.settings.petsc_options
        read_rtol, read_atol, read_divtol, read_max_it = self._read_tolerances
        ksp.setTolerances(rtol=read_rtol if "ksp_rtol" in user else rtol,
                          atol=read_atol if "ksp_atol" in user else 0.0,
                          divtol=read_divtol,
                          max_it=read_max_it if "ksp_max_it" in user else self.max_it)

    @property
    def has_factorization(self) -> bool:
        return self._factorized

    def _get_ksp(self, A) -> PETSc.KSP:
        if self._ksp is not None:
            return self._ksp
        s = self.settings
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOptionsPrefix(self.prefix)
        opts = PETSc.Options()
        if s.linear_solver == "direct":
            defaults = {"ksp_type": "preonly",
                        "pc_type": "cholesky", "pc_factor_mat_solver_type": "mumps",
                        "mat_mumps_icntl_14": 200}
        else:
            defaults = {"ksp_type": "cg", "pc_type": "gamg", "pc_gamg_type": "agg",
                        "mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi"}
        for k, v in {**defaults, **s.petsc_options}.items():
            opts[f"{self.prefix}{k}"] = v
        # the settings' tolerances first, so that setFromOptions lets a user's ksp_* win
        ksp.setTolerances(rtol=s.krylov_rtol, atol=0.0, max_it=self.max_it)
        ksp.setFromOptions()
        self._read_tolerances = ksp.getTolerances()  # (rtol, atol, divtol, max_it) as read
        if ksp.getType() != "preonly":
            ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
            ksp.getPC().setReusePreconditioner(False)
        if s.linear_solver == "gamg":
            A.setNearNullSpace(_rigid_body_modes(A, self.coordinates, self.comm))
        self._ksp = ksp
        return ksp

    def solve(self, J: Jacobian, rhs, du, rtol: float) -> None:
        A = J.petsc()
        ksp = self._get_ksp(A)
        self._set_tolerances(ksp, rtol)
        ksp.getPC().setReusePreconditioner(False)  # a new factorisation of this J
        ksp.setOperators(A, A)
        self.counts.factorizations += 1
        with blas.outer():  # MUMPS' factorisation: level-3 BLAS
            ksp.solve(rhs, du)
        its, reason = ksp.getIterationNumber(), ksp.getConvergedReason()
        self.counts.krylov_iterations += its
        if not self._factorized:
            self._report_unused_options()
        if reason < 0:
            raise StepFailure(f"linear solver failed (PETSc KSP reason {reason} after {its} "
                              "iterations)")
        self._factorized = True
        _ghost_update(du)

    def _report_unused_options(self) -> None:
        """After the first solve every option PETSc uses has been read: warn (rank 0) about
        the user's petsc_options it never read, a typo or an option of another solver.
        """
        unused = [k for k in self.settings.petsc_options
                  if not _option_used(f"{self.prefix}{k}")]
        self.unused_options = unused
        if unused and self.comm.rank == 0 and tuple(unused) not in _warned_unused:
            _warned_unused.add(tuple(unused))  # once per process, not once per simulation
            log.warning("petsc_options %s: never read by PETSc (misspelt, or not an option "
                        "of the solver that runs); they have no effect",
                        ", ".join(repr(k) for k in unused))

    def back_solve(self, rhs, du) -> bool:
        """A solve with the operators as they are: for a direct KSP a back-solve with the kept
        factorisation (the operator is unchanged, or the reuse flag is on).
        """
        if self._ksp is None:
            return False
        self.counts.back_solves += 1
        self._ksp.solve(rhs, du)
        ok = self._ksp.getConvergedReason() > 0
        if ok:
            _ghost_update(du)
        return ok

    def solve_near(self, J: Jacobian, rhs, du, rtol: float, maxit: int) -> bool:
        """GMRES on J preconditioned with the last MUMPS factorisation, kept
        (``PCSetReusePreconditioner``) although J changed. The reuse flag stays on, so
        back-solves keep using that factorisation until :meth:`solve` asks for a new one.
        """
        if not (self.solves_near and self._factorized):
            return False
        A = J.petsc()
        ksp = self._get_ksp(A)
        ksp.getPC().setReusePreconditioner(True)
        ksp.setType(PETSc.KSP.Type.GMRES)
        ksp.setPCSide(PETSc.PC.Side.RIGHT)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.setTolerances(rtol=rtol, atol=0.0, max_it=maxit)
        ksp.setOperators(A, A)
        try:
            ksp.solve(rhs, du)
            its, ok = ksp.getIterationNumber(), ksp.getConvergedReason() > 0
        finally:
            ksp.setType(PETSc.KSP.Type.PREONLY)
        self.counts.krylov_iterations += its
        if ok:
            _ghost_update(du)
        return ok


def _rigid_body_modes(A, x: np.ndarray, comm):
    """The six rigid-body modes of the owned dofs (block coordinates ``x``), orthonormalised,
    as GAMG's near-nullspace (collective).
    """
    vecs = [A.createVecLeft() for _ in range(6)]
    for i in range(3):
        vecs[i].array.reshape(-1, 3)[:, i] = 1.0
    for k, (i, j) in enumerate(((0, 1), (1, 2), (2, 0))):
        a = vecs[3 + k].array.reshape(-1, 3)
        a[:, i] = -x[:, j]
        a[:, j] = x[:, i]
    for v in vecs:
        v.assemble()
    for i, v in enumerate(vecs):
        for w in vecs[:i]:
            v.axpy(-v.dot(w), w)
        v.scale(1.0 / v.norm())
    return PETSc.NullSpace().create(vectors=vecs, comm=comm)


def factorization_mode(settings: SolverSettings, comm_size: int, element: str = "lagrange",
                       degree: int = 1, quadrature_degree: int | None = None) -> str | None:
    """"pardiso"/"single"/"double" when the rule table (:mod:`data_spec.solver_rules`) sends
    the settings to the serial factorisations, else None (PETSc's KSP). ValueError naming the
    keys for a combination the table does not have.

    ``auto`` on one process is "pardiso" when MKL is installed (float32 Cholesky, faster than
    MUMPS' LDL^T and threaded: ``bench/bench_jacobian.py``), else "single" (MUMPS' float32
    LDL^T with METIS ordering).
    """
    s = settings
    path = solver_rules.linear_path(s.linear_solver, s.factorization, s.petsc_options,
                                    comm_size, element, degree, quadrature_degree)
    if path != "serial":
        return None
    mode = s.factorization
    if ldlt.load() is None:
        if mode != "auto" or element == "anp":
            raise ValueError(f"settings.factorization = {mode!r} needs the compiled MUMPS "
                             "extension (fem_sim/solver/ldlt_kernel.c: the LDL^T for matrices "
                             "the Cholesky refuses), which did not build")
        return None
    if mode == "pardiso" and not pardiso.available():
        raise ValueError("settings.factorization = 'pardiso' needs MKL (pip install mkl, "
                         "done by make setup); 'auto' falls back to MUMPS without it")
    if mode == "auto":
        return "pardiso" if pardiso.available() else "single"
    return mode


def make_linear_solver(settings: SolverSettings, comm, prefix: str, mode: str | None,
                       coordinates: np.ndarray | None = None) -> LinearSolver:
    """The solver of :func:`factorization_mode`'s ``mode`` (None: PETSc's KSP);
    ``coordinates`` (owned dof blocks) for GAMG.
    """
    if mode is not None:
        return SerialLDLTSolver(settings, mode)
    return PetscSolver(settings, comm, prefix, coordinates)
