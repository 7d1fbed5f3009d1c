"""The serial LDL^T (MUMPS C interface, METIS ordering) against dense linear algebra."""

import numpy as np
import pytest
import scipy.sparse as sp
from mpi4py import MPI  # noqa: F401  (MPI must be initialised for MUMPS)

from fem_sim.solver import ldlt


def laplacian_3d(n: int, bs: int = 3, shift: float = 0.0) -> sp.csr_matrix:
    """A block (bs x bs per node) 7-point Laplacian on an n^3 grid, minus shift * I."""
    one = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    eye = sp.identity(n)
    lap = (sp.kron(sp.kron(one, eye), eye) + sp.kron(sp.kron(eye, one), eye)
           + sp.kron(sp.kron(eye, eye), one))
    block = np.array([[2.0, 0.5, 0.0], [0.5, 2.0, 0.3], [0.0, 0.3, 1.5]])[:bs, :bs]
    A = sp.kron(lap, block) - shift * sp.identity(n**3 * bs)
    return sp.csr_matrix(A)


@pytest.fixture(scope="module", autouse=True)
def extension(compiled):
    compiled("ldlt")  # needs gcc, libmumps-dev, libmetis-dev


@pytest.mark.parametrize("pivoting", [True, False])  # MUMPS SYM=2, SYM=1 (the float32 default)
@pytest.mark.parametrize("precision", ["double", "single"])
@pytest.mark.parametrize("shift", [0.0, 1.3])  # SPD, and indefinite
def test_solves_match_dense_and_inertia_is_exact(precision, shift, pivoting):
    """Without pivoting too: an indefinite matrix with no zero leading minor factorises, and
    the negative pivots still count its negative eigenvalues (Sylvester's law of inertia)."""
    A = laplacian_3d(5, shift=shift)
    dense = A.toarray()
    b = np.random.default_rng(0).normal(size=A.shape[0])
    solver = ldlt.SerialLDLT(precision, bs=3, pivoting=pivoting)
    solver.factor(A.indptr, A.indices, A.data)
    exact = np.linalg.solve(dense, b)
    one = solver.solve(b)
    err = np.linalg.norm(one - exact) / np.linalg.norm(exact)
    cond = np.linalg.cond(dense)
    eps = np.finfo(np.float32 if precision == "single" else np.float64).eps
    assert err <= 50 * cond * eps, (err, cond)
    x, its, ok = solver.solve_refined(A, b, 1e-12)
    assert ok and its <= (2 if precision == "double" else 6), its
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)
    # LDL^T gives the inertia: negative pivots = negative eigenvalues
    assert solver.negative_pivots == int(np.sum(np.linalg.eigvalsh(dense) < 0))
    assert (shift > 0) == (solver.negative_pivots > 0)


def test_metis_and_mumps_orderings_give_the_same_solution():
    """(How many operations each ordering costs is a benchmark: bench/bench_jacobian.py.)"""
    A = laplacian_3d(12)
    nd = ldlt.SerialLDLT("double", bs=3)
    nd.factor(A.indptr, A.indices, A.data)
    # A block size that does not divide n = 3 * 12^3 = 5184: no METIS ordering is computed and
    # MUMPS orders the matrix itself (AMD).
    own = ldlt.SerialLDLT("double", bs=7)
    own.factor(A.indptr, A.indices, A.data)
    assert nd.flops > 0 and own.flops > 0
    b = np.ones(A.shape[0])
    np.testing.assert_allclose(nd.solve(b), own.solve(b), rtol=1e-10)


def test_new_pattern_is_analysed_again_and_values_refactorised():
    A = laplacian_3d(4)
    solver = ldlt.SerialLDLT("double", bs=3)
    solver.factor(A.indptr, A.indices, A.data)
    solver.factor(A.indptr, A.indices, 2.0 * A.data)  # same pattern: no new analysis
    assert (solver.analyses, solver.factorizations) == (1, 2)
    b = np.ones(A.shape[0])
    np.testing.assert_allclose(2.0 * (A @ solver.solve(b)), b, rtol=1e-10)
    B = laplacian_3d(3)
    solver.factor(B.indptr, B.indices, B.data)
    assert solver.analyses == 2
    np.testing.assert_allclose(B @ solver.solve(np.ones(B.shape[0])), 1.0, rtol=1e-10)


def test_shared_ordering_is_used_only_for_the_same_pattern():
    """share_ordering: a second instance on the pattern the first analysed takes its METIS
    ordering (the same array, no second METIS run) and solves alike; on another pattern it
    orders for itself."""
    A = laplacian_3d(6)
    first = ldlt.SerialLDLT("single", bs=3, pivoting=False)
    first.factor(A.indptr, A.indices, A.data)
    second = ldlt.SerialLDLT("single", bs=3, pivoting=False)
    second.share_ordering(first)
    second.factor(A.indptr, A.indices, 3.0 * A.data)
    assert second._perm_in is first._perm_in and second.analyses == 1
    b = np.ones(A.shape[0])
    np.testing.assert_allclose(3.0 * second.solve(b), first.solve(b), rtol=1e-5)
    B = laplacian_3d(5)
    third = ldlt.SerialLDLT("single", bs=3, pivoting=False)
    third.share_ordering(first)
    third.factor(B.indptr, B.indices, B.data)
    assert third._perm_in is not first._perm_in and third._perm_in.size == B.shape[0]
    np.testing.assert_allclose(B @ third.solve(np.ones(B.shape[0])), 1.0, rtol=1e-4)


def test_singular_matrix_raises_a_factor_error():
    A = laplacian_3d(3).tolil()
    A[5, :] = 0.0
    A[:, 5] = 0.0
    A = sp.csr_matrix(A)  # explicit zeros stay in the pattern
    solver = ldlt.SerialLDLT("double", bs=3)
    with pytest.raises(ldlt.FactorError, match="INFOG"):
        solver.factor(A.indptr, A.indices, A.data)


def test_gmres_reports_non_convergence():
    A = laplacian_3d(3)
    b = np.ones(A.shape[0])
    x, its, ok = ldlt.gmres(A.dot, lambda v: v, b, 1e-14, 3)  # unpreconditioned, 3 its
    assert not ok and its == 3
    x, its, ok = ldlt.gmres(A.dot, lambda v: v, b, 1e-10, A.shape[0])
    assert ok and np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)


def test_threaded_csr_product_matches_scipy(compiled):
    """GMRES' matvec (fem_sim.solver.tet.CsrOperator, rows split among the threads): scipy's
    product to round-off, the same bits on one and two threads."""
    from fem_sim.material import ogden_c
    from fem_sim.solver import tet

    compiled("tet")
    A = sp.csr_matrix(laplacian_3d(7) + sp.random(1029, 1029, 0.01, random_state=2))
    A.sort_indices()
    op = tet.operator(A.indptr, A.indices, A.data)
    assert isinstance(op, tet.CsrOperator)
    x = np.random.default_rng(6).standard_normal(A.shape[0])
    before = ogden_c.threads()
    try:
        ys = [(ogden_c.threads(n), op.dot(x))[1] for n in (1, 2)]
    finally:
        ogden_c.threads(before)
    np.testing.assert_allclose(ys[0], A @ x, rtol=0, atol=1e-13 * np.abs(A @ x).max())
    assert np.array_equal(ys[0], ys[1])
    with pytest.raises(ValueError, match="expected"):
        op.dot(x[:-1])


def test_gmres_checks_the_true_residual_only_when_the_estimate_converges():
    """One matvec per iteration plus one per true-residual check (the Arnoldi estimate decides
    when to check): preconditioned with the factors of a nearby matrix, a few checks in all."""
    A = laplacian_3d(6)
    b = np.random.default_rng(3).standard_normal(A.shape[0])
    near = sp.csr_matrix(A + sp.diags(0.3 * np.random.default_rng(4).random(A.shape[0])))
    solver = ldlt.SerialLDLT("single", bs=1)
    solver.factor(near.indptr, near.indices, near.data)
    calls = []

    def matvec(v):
        calls.append(1)
        return A @ v

    x, its, ok = ldlt.gmres(matvec, solver.solve, b, 1e-12, 30)
    assert ok and np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)
    assert 4 <= its < 20 and len(calls) <= its + 2


# ----------------------------------------------------------------------------------------------
# MKL PARDISO's float32 Cholesky (fem_sim/solver/pardiso.py)
# ----------------------------------------------------------------------------------------------
def test_make_setup_installs_mkl():
    """The solver environment has MKL (requirements/solver-extras.txt), so the serial default
    is PARDISO's Cholesky; the tests below would otherwise skip."""
    from fem_sim.solver import linear, pardiso
    from fem_sim.solver.settings import SolverSettings

    assert pardiso.available(), "MKL's libmkl_rt is missing from the solver environment"
    assert linear.factorization_mode(SolverSettings(), 1) == "pardiso"


def test_without_mkl_auto_is_mumps_and_pardiso_is_refused(monkeypatch):
    from fem_sim.solver import linear, pardiso
    from fem_sim.solver.settings import SolverSettings

    monkeypatch.setattr(pardiso, "available", lambda: False)
    assert linear.factorization_mode(SolverSettings(), 1) == "single"
    with pytest.raises(ValueError, match="needs MKL"):
        linear.factorization_mode(SolverSettings(factorization="pardiso"), 1)
    with pytest.raises(ValueError, match="not a supported combination"):
        linear.factorization_mode(SolverSettings(factorization="pardiso"), 2)


@pytest.fixture
def cholesky():
    from fem_sim.solver import pardiso

    if not pardiso.available():
        pytest.skip("MKL is not installed")
    return pardiso.PardisoCholesky


def test_pardiso_cholesky_matches_dense_and_refines(cholesky):
    A = laplacian_3d(6)
    b = np.random.default_rng(1).normal(size=A.shape[0])
    solver = cholesky()
    solver.factor(A.indptr, A.indices, A.data)
    exact = np.linalg.solve(A.toarray(), b)
    err = np.linalg.norm(solver.solve(b) - exact) / np.linalg.norm(exact)
    cond = np.linalg.cond(A.toarray())
    assert err <= 50 * cond * np.finfo(np.float32).eps, (err, cond)
    assert err > 1e-10  # float32 factors: not a double-precision solve
    x, its, ok = solver.solve_refined(A, b, 1e-12)
    assert ok and its <= 6, its
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)
    assert solver.flops > 0 and solver.negative_pivots == 0


def test_pardiso_analyses_once_per_pattern(cholesky):
    A = laplacian_3d(5)
    first = cholesky()
    first.factor(A.indptr, A.indices, A.data)
    first.factor(A.indptr, A.indices, 2.0 * A.data)
    assert (first.analyses, first.factorizations) == (1, 2)
    b = np.ones(A.shape[0])
    np.testing.assert_allclose(2.0 * (A @ first.solve(b)), b, rtol=1e-4)
    # PARDISO's nested dissection: a permutation of the dofs, not the identity
    assert np.array_equal(np.sort(first._perm), np.arange(A.shape[0]))
    assert not np.array_equal(first._perm, np.arange(A.shape[0]))
    B = laplacian_3d(4)
    first.factor(B.indptr, B.indices, B.data)
    assert first.analyses == 2
    np.testing.assert_allclose(B @ first.solve(np.ones(B.shape[0])), 1.0, rtol=1e-4)


def test_pardiso_instances_share_one_analysis_and_keep_their_own_factors(cholesky):
    """share_ordering: the second instance factorises with the first one's analysis (no second
    ordering) and both keep their own factors; a new pattern gives the sharer a handle of its
    own and leaves the other's factors intact."""
    A = laplacian_3d(5)
    first, second = cholesky(), cholesky()
    first.factor(A.indptr, A.indices, A.data)
    second.share_ordering(first)
    second.factor(A.indptr, A.indices, 3.0 * A.data)
    assert (first.analyses, second.analyses) == (1, 0)
    b = np.ones(A.shape[0])
    np.testing.assert_allclose(A @ first.solve(b), b, rtol=1e-4)
    np.testing.assert_allclose(3.0 * (A @ second.solve(b)), b, rtol=1e-4)
    third = cholesky()
    third.share_ordering(first)  # the handle serves two: the third keeps its own
    third.factor(A.indptr, A.indices, A.data)
    assert third.analyses == 1
    B = laplacian_3d(4)
    second.factor(B.indptr, B.indices, B.data)
    assert second.analyses == 1
    np.testing.assert_allclose(B @ second.solve(np.ones(B.shape[0])), 1.0, rtol=1e-4)
    np.testing.assert_allclose(A @ first.solve(b), b, rtol=1e-4)
    second.free()
    np.testing.assert_allclose(A @ first.solve(b), b, rtol=1e-4)


def test_pardiso_refuses_an_indefinite_matrix_and_the_solver_falls_back(cholesky, monkeypatch):
    """Cholesky cannot factorise an indefinite matrix (FactorError, not wrong factors); the
    linear solver then factorises it with MUMPS' LDL^T, counts that, and solves it."""
    from fem_sim.solver import linear
    from fem_sim.solver.settings import SolverSettings

    indefinite, spd = laplacian_3d(5, shift=1.3), laplacian_3d(5)
    with pytest.raises(ldlt.FactorError, match="not positive definite"):
        cholesky().factor(indefinite.indptr, indefinite.indices, indefinite.data)

    class Jacobian:  # the interface the linear solver uses
        def __init__(self, A):
            self.A = A

        def csr(self):
            return self.A.indptr, self.A.indices, self.A.data

    class Vec:
        def __init__(self, a):
            self.array = self.array_r = a

    monkeypatch.setattr(linear, "_ghost_update", lambda vec: None)  # plain arrays here
    solver = linear.SerialLDLTSolver(SolverSettings(), "pardiso")
    b = np.random.default_rng(2).normal(size=spd.shape[0])
    for A, fallbacks in ((indefinite, 1), (spd, 1)):
        du = Vec(np.zeros_like(b))
        solver.solve(Jacobian(A), Vec(b), du, 1e-11)
        assert solver.counts.cholesky_fallbacks == fallbacks
        assert np.linalg.norm(A @ du.array - b) <= 1e-11 * np.linalg.norm(b)
    assert solver.counts.factorizations == 2
    assert isinstance(solver._ldlt, cholesky)  # the SPD matrix: Cholesky's factors


def test_pardiso_keeps_its_threads_when_gmsh_starts(cholesky, tmp_path):
    """gmsh.initialize() sets libgomp's thread count to 1 (General.NumThreads), which MKL's
    GNU threading layer followed: PARDISO then crashed on factors made with two threads
    (SIGSEGV, seen with MKL 2026.2). Its count is now set explicitly. In a subprocess: a crash
    must fail this test, not kill the test run."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    script = tmp_path / "gmsh_then_pardiso.py"
    script.write_text("""
import sys
import numpy as np
from mpi4py import MPI  # noqa: F401
from tests.fem_sim.test_ldlt import laplacian_3d
from fem_sim.solver import pardiso
A = laplacian_3d(12)
P = pardiso.PardisoCholesky()
P.factor(A.indptr, A.indices, A.data)
before = pardiso.threads()
import gmsh
gmsh.initialize()
gmsh.finalize()
P.factor(A.indptr, A.indices, A.data)
x = P.solve(np.ones(A.shape[0]))
print(before, pardiso.threads(), float(np.abs(A @ x - 1.0).max()))
""")
    env = {**os.environ, "OMP_NUM_THREADS": "2", "PETSC_OPTIONS": "-no_signal_handler",
           "PYTHONPATH": str(Path(__file__).parents[2])}  # the script imports tests.fem_sim
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         env=env, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    before, after, err = out.stdout.split()[-3:]
    assert before == after == "2" and float(err) < 1e-2


# ----------------------------------------------------------------------------------------------
# OpenBLAS' threads in the load-step loop (fem_sim/solver/blas.py)
# ----------------------------------------------------------------------------------------------
def test_openblas_threads_are_scoped():
    """One OpenBLAS thread inside the scope, the outer count back in ``outer()`` (MUMPS'
    factorisations) and after the scope."""
    from fem_sim.solver import blas

    if blas.count() == 0:
        pytest.skip("numpy does not use OpenBLAS here")
    n = blas.count()  # the process's own count (OPENBLAS_NUM_THREADS, capped at the cores)
    with blas.threads(1):
        assert blas.count() == 1
        with blas.outer():
            assert blas.count() == n
        assert blas.count() == 1
    assert blas.count() == n
    with blas.threads(2), blas.threads(1), blas.outer():  # the outermost scope's "before"
        assert blas.count() == n
    assert blas.count() == n


def test_load_steps_run_openblas_on_one_thread(monkeypatch):
    """The Newton loop's vector operations run with one OpenBLAS thread (idle OpenBLAS threads
    spin on the cores the OpenMP kernels and PARDISO need); the caller's count comes back."""
    from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
    from fem_sim.geometry.phantom import make_phantom
    from fem_sim.solver import blas
    from fem_sim.solver.equations import Equations

    if blas.count() == 0:
        pytest.skip("numpy does not use OpenBLAS here")
    seen = []
    residual = Equations.residual

    def spy(self, lam):
        seen.append(blas.count())
        return residual(self, lam)

    monkeypatch.setattr(Equations, "residual", spy)
    g = make_phantom(0, 25.0)
    prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells)
    node = int(g.surface_nodes[np.argmin(g.points[g.surface_nodes, 2])])
    with blas.threads(2):
        sol = prob.solve(OgdenMaterial((4.1e-3,), (10.06,), 0.41),
                         [Constraint(g.regions["vena_cava"])],
                         [NodalLoad([node], [[0.0, 0.0, -0.05]])], [0.5, 1.0])
        assert blas.count() == 2
    assert sol.status == "ok" and seen and set(seen) == {1}
