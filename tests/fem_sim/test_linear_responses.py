"""OgdenProblem.linear_responses: the body linearised at u = 0, against closed-form small-strain
elasticity, Maxwell-Betti reciprocity and the nonlinear solve at a small load."""

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
