"""OgdenProblem.linear_responses: the body linearised at u = 0, against closed-form small-strain
elasticity, Maxwell-Betti reciprocity and the nonlinear solve at a small load; its second-order
term (OgdenProblem.load_expansion) against the homogeneous bar and the O(lam^3) limit."""

import numpy as np
import pytest

from data_spec.geometry import boundary_triangles
from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
from tests.fixtures import box_mesh

C1 = 4.1e-3
MAT = OgdenMaterial((C1,), (10.06,), 100 * C1)   # the shipped scenes' liver


def _problem(degree: int, n: int = 2):
    from mpi4py import MPI

    g = box_mesh(n)
    return g, OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=degree,
                           settings={"rtol": 1e-12, "atol": 1e-14})


def _face_loads(g, traction: float) -> NodalLoad:
    """The consistent P1 nodal forces of a uniform traction (MPa, along x) on the face x = 1:
    a third of each boundary triangle's area to each of its corners.
    """
    tri = boundary_triangles(g.cells, g.points)
    tri = tri[np.all(g.points[tri, 0] == 1.0, axis=1)]
    area = 0.5 * np.linalg.norm(np.cross(g.points[tri[:, 1]] - g.points[tri[:, 0]],
                                         g.points[tri[:, 2]] - g.points[tri[:, 0]]), axis=1)
    f = np.zeros((g.n_nodes, 3))
    np.add.at(f[:, 0], tri.ravel(), np.repeat(traction * area / 3.0, 3))
    nodes = np.unique(tri)
    return NodalLoad(nodes, f[nodes])


def test_uniaxial_stress_closed_form():
    """Rollers on x = 0, y = 0, z = 0 and a traction t on x = 1: u = (t/E) (x, -nu y, -nu z)
    with the small-strain moduli of the Ogden law, mu = c1/2 = 2.05e-3 MPa, K = 0.41 MPa:
    E = 9 K mu / (3 K + mu) = 6.1398e-3 MPa, nu = (3 K - 2 mu) / (2 (3 K + mu)) = 0.49750.
    P1 is exact for a homogeneous strain.
    """
    g, prob = _problem(1)
    x = g.points
    rollers = [Constraint(np.flatnonzero(x[:, i] == 0.0), (i,), 0.0) for i in range(3)]
    t = 1e-3
    u = prob.linear_responses(MAT, rollers, [[_face_loads(g, t)]])
    mu, k = C1 / 2, 100 * C1
    e = 9 * k * mu / (3 * k + mu)
    nu = (3 * k - 2 * mu) / (2 * (3 * k + mu))
    assert abs(e - 6.1398e-3) < 1e-7 and abs(nu - 0.49750) < 1e-5
    expected = (t / e) * np.column_stack([x[:, 0], -nu * x[:, 1], -nu * x[:, 2]])
    np.testing.assert_allclose(u[0], expected, atol=1e-6 * np.abs(expected).max())


@pytest.mark.parametrize("degree", [1, 2], ids=["P1", "P2"])
def test_reciprocity_and_small_load_limit(degree):
    """Maxwell-Betti: the work of load b on load a's displacement equals that of a on b's (the
    small-strain tangent is symmetric). And the nonlinear solve at a load fraction of 1e-4,
    divided by it, is the linear response with a gap that closes as the fraction (first
    order); at fraction 1 it is not the linear response.
    """
    g, prob = _problem(degree, n=3)
    x = g.points
    fixed = [Constraint(np.flatnonzero(x[:, 0] == 0.0))]
    tip = np.flatnonzero((x[:, 0] == 1.0) & (x[:, 2] == 1.0))
    top = np.flatnonzero((x[:, 2] == 1.0) & (x[:, 0] == 0.0 + 1.0 / 3.0))
    a = NodalLoad(tip[:1], [[0.0, 0.3, -0.2]])
    b = NodalLoad(top[-1:], [[0.1, -0.1, -0.4]])
    ua, ub = prob.linear_responses(MAT, fixed, [[a], [b]], rtol=1e-10)
    wab = ub[a.nodes[0]] @ a.forces[0]
    wba = ua[b.nodes[0]] @ b.forces[0]
    assert abs(wab - wba) <= 1e-6 * abs(wab) and abs(wab) > 0
    big = NodalLoad(a.nodes, a.forces * 3e-4)   # strains of ~10 % at fraction 1
    ulin = prob.linear_responses(MAT, fixed, [[big]])[0]
    sol = prob.solve(MAT, fixed, [big], [1e-4, 1e-3, 1.0])
    assert sol.status == "ok", sol.failure_reason
    scale = np.abs(ulin).max()
    d1, d2, d3 = (np.abs(u / lam - ulin).max() / scale
                  for u, lam in zip(sol.displacement, (1e-4, 1e-3, 1.0)))
    assert d1 <= 5e-4
    assert 5.0 < d2 / d1 < 20.0   # the gap closes as the load fraction: first order
    assert d3 >= 0.05             # the liver's stiffening shows at fraction 1


def test_second_order_uniaxial_closed_form():
    """The load's second-order term of the homogeneous uniaxial bar (rollers, dead traction t
    on x = 1), from the energy in log-stretches p = ln a, q = ln b (stretches (a, b, b)),
    d = p - q: W = c/m^2 (e^(2md/3) + 2 e^(-md/3) - 3) + K/2 (p + 2q)^2. P22 = 0 gives
    K (p + 2q) = g(d)/2 with g = 2c/(3m) (e^(2md/3) - e^(-md/3)) = (2c/3)(d + m d^2/6 + ...),
    and P11 = t gives t = (3/2) g e^-p. In tau = t/c, to second order:
    p = A tau + (B - A s) tau^2, q = C tau + (B - C s) tau^2, with A = 2/3 + c/(9K),
    C = c/(9K) - 1/3, s = m/6 - A, B = c m/(54K); so a - 1 = A tau + (B - A s + A^2/2) tau^2
    and b - 1 = C tau + (B - C s + C^2/2) tau^2: -0.448888 and 0.392224 for the shipped liver
    (A = 1/E c and C = -nu/E c: the first-order term is the linear test's).
    """
    g, prob = _problem(1)
    x = g.points
    rollers = [Constraint(np.flatnonzero(x[:, i] == 0.0), (i,), 0.0) for i in range(3)]
    t, c, m, k = 1e-3, C1, 10.06, 100 * C1
    u = prob.load_expansion(MAT, rollers, [[_face_loads(g, t)]], order=2, rtol=1e-10)[0]
    a_, c_ = 2 / 3 + c / (9 * k), c / (9 * k) - 1 / 3
    s, b_ = m / 6 - a_, c * m / (54 * k)
    qa, qb = b_ - a_ * s + a_**2 / 2, b_ - c_ * s + c_**2 / 2
    assert abs(qa + 0.448888) < 1e-5 and abs(qb - 0.392224) < 1e-5
    tau = t / c
    first = tau * np.column_stack([a_ * x[:, 0], c_ * x[:, 1], c_ * x[:, 2]])
    second = tau**2 * np.column_stack([qa * x[:, 0], qb * x[:, 1], qb * x[:, 2]])
    np.testing.assert_allclose(u[0], first, atol=1e-6 * np.abs(first).max())
    np.testing.assert_allclose(u[1], second, atol=1e-5 * np.abs(second).max())


@pytest.mark.parametrize("degree", [1, 2], ids=["P1", "P2"])
def test_second_order_limit_of_the_nonlinear_solve(degree):
    """A cantilever under a tip force: lam u1 + lam^2 u2 misses the nonlinear solution by
    O(lam^3) (the gap falls 8-fold when lam halves), lam u1 alone by O(lam^2) (4-fold); the
    second-order term is what the body adds beyond the linear response.
    """
    g, prob = _problem(degree, n=3)
    x = g.points
    fixed = [Constraint(np.flatnonzero(x[:, 0] == 0.0))]
    tip = np.flatnonzero((x[:, 0] == 1.0) & (x[:, 2] == 1.0))
    load = NodalLoad(tip[:1], [[0.0, 3e-4 * 0.3, -3e-4 * 0.2]])
    u1, u2 = prob.load_expansion(MAT, fixed, [[load]], order=2, rtol=1e-10)[0]
    np.testing.assert_allclose(u1, prob.linear_responses(MAT, fixed, [[load]], rtol=1e-10)[0],
                               atol=1e-9 * np.abs(u1).max())
    lams = [0.005, 0.01, 0.02]
    sol = prob.solve(MAT, fixed, [load], lams)
    assert sol.status == "ok", sol.failure_reason
    one = [np.abs(u - lam * u1).max() for u, lam in zip(sol.displacement, lams)]
    two = [np.abs(u - lam * u1 - lam**2 * u2).max() for u, lam in zip(sol.displacement, lams)]
    assert all(3.5 < hi / lo < 4.5 for lo, hi in zip(one[:-1], one[1:])), one
    assert all(7.0 < hi / lo < 9.0 for lo, hi in zip(two[:-1], two[1:])), two
    assert two[0] < 0.05 * one[0]


@pytest.mark.parametrize("factorization", ["auto", "single"], ids=["default", "MUMPS"])
@pytest.mark.parametrize("degree", [1, 2], ids=["P1", "P2"])
def test_unit_responses_are_the_linear_responses_of_unit_nodal_forces(degree, factorization):
    """The block solve of the Green's function (float64 factors, kept) against one PETSc
    MUMPS solve per unit load (the base class's row loop: another solver's path)."""
    from mpi4py import MPI

    g = box_mesh(3)
    prob, ref = (OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=degree,
                              settings={"factorization": f}) for f in (factorization, "petsc"))
    x = g.points
    fixed = [Constraint(np.flatnonzero(x[:, 0] == 0.0))]
    nodes = np.flatnonzero(x[:, 0] == 1.0)[:4]
    green = prob.unit_responses(MAT, fixed, nodes, rtol=1e-8)
    loads = [[NodalLoad([n], [e])] for n in nodes for e in np.eye(3)]
    each = ref.linear_responses(MAT, fixed, loads, rtol=1e-8)
    np.testing.assert_allclose(green.reshape(each.shape), each, rtol=0,
                               atol=1e-6 * np.abs(each).max())
    assert np.abs(each).max() > 0
    made = prob.linear.counts.factorizations
    again = prob.linear_responses(MAT, fixed, loads[:2], rtol=1e-8)   # the same matrix
    np.testing.assert_allclose(again, each[:2], rtol=0, atol=1e-6 * np.abs(each).max())
    assert prob.linear.counts.factorizations == made


def test_a_blocks_residual_in_chunks_is_the_whole_products(monkeypatch):
    """fem_sim.solver.linear.block_residual, chunk by chunk (3 rows here), is B - (A X^T)^T
    of the rows asked, in their order."""
    import scipy.sparse as sp

    import fem_sim.solver.linear as linear

    rng = np.random.default_rng(0)
    A = sp.random(40, 40, density=0.2, random_state=1, format="csr") + sp.eye(40, format="csr")
    B, X = rng.normal(size=(10, 40)), rng.normal(size=(10, 40))
    rows = np.array([7, 0, 3, 9, 1, 4, 8])
    monkeypatch.setattr(linear, "BLOCK_ROWS", 3)
    np.testing.assert_allclose(linear.block_residual(A, B, X, rows),
                               B[rows] - (A @ X[rows].T).T, rtol=1e-14, atol=1e-13)
    assert linear.block_residual(A, B, X, rows[:0]).shape == (0, 40)


def test_random_probes_vouch_for_a_blocks_rows_and_catch_a_single_bad_one():
    """fem_sim.solver.linear.rows_surely_within: exact solves of 300 right-hand sides pass;
    one row of them off by 1e-4 of its size (rtol 1e-6) fails the probes, whichever row,
    and so goes to the row-by-row check."""
    import scipy.sparse as sp

    import fem_sim.solver.linear as linear

    rng = np.random.default_rng(3)
    n = 60
    M = sp.random(n, n, density=0.1, random_state=2)
    A = (M @ M.T + n * sp.eye(n)).tocsr()
    B = rng.normal(size=(300, n))
    X = np.linalg.solve(A.toarray(), B.T).T
    size = linear.row_norms(B)
    np.testing.assert_allclose(size, np.linalg.norm(B, axis=1), rtol=1e-14)
    assert linear.rows_surely_within(A, B, X, size, 1e-6)
    for row in (0, 137, 299):
        bad = X.copy()
        bad[row] += 1e-4 * size[row] / n * rng.normal(size=n)
        rel = np.linalg.norm(B[row] - A @ bad[row]) / size[row]
        assert rel > 1e-6
        for seed in range(5):
            assert not linear.rows_surely_within(A, B, bad, size, 1e-6, seed=seed)
