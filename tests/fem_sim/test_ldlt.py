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
