"""Homogeneous deformations of a unit cube against closed-form answers (scipy on the 1-D
equations of conftest.ogden_cauchy), for P1 and P2 and both volumetric functions."""

import numpy as np
import pytest
from scipy.optimize import brentq

from fem_sim import Constraint, OgdenMaterial, OgdenProblem
from tests.fixtures import box_mesh

C, M = (4.1e-3,), (10.06,)
K = 200 * 4.1e-3 / 2  # K/mu = 200


@pytest.fixture(scope="module", params=[1, 2], ids=["P1", "P2"])
def cube(request):
    from mpi4py import MPI

    g = box_mesh(2)
    return g.points, OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=request.param,
                                  settings={"rtol": 1e-12, "atol": 1e-14})


def symmetric_rollers(x):
    return [Constraint(np.flatnonzero(x[:, i] == 0.0), (i,), 0.0) for i in range(3)]


def face_reaction(prob, x, axis):
    return prob.reaction(np.flatnonzero(x[:, axis] == 1.0))[axis]


@pytest.mark.parametrize("vol", ["log", "quadratic"])
@pytest.mark.parametrize("lam", [0.6, 0.8, 1.25, 1.6])
def test_uniaxial(cube, cauchy, lam, vol):
    x, prob = cube
    mat = OgdenMaterial(C, M, K, vol)
    cons = symmetric_rollers(x) + [Constraint(np.flatnonzero(x[:, 0] == 1.0), (0,), lam - 1)]
    sol = prob.solve(mat, cons, [], np.linspace(0.1, 1.0, 10))
    assert sol.status == "ok", sol.failure_reason
    # Closed form: lateral stretch l2 = l3 with sigma_22 = 0; nominal stress P11 = sigma_11 J/l1.
    l2 = brentq(lambda t: cauchy([lam, t, t], C, M, K, vol)[1], 0.3, 3.0, xtol=1e-15)
    s = cauchy([lam, l2, l2], C, M, K, vol)
    P11 = s[0] * l2 * l2
    u = sol.displacement[-1]
    np.testing.assert_allclose(1 + u[x[:, 1] == 1.0, 1], l2, rtol=1e-9)
    np.testing.assert_allclose(1 + u[x[:, 2] == 1.0, 2], l2, rtol=1e-9)
    assert abs(face_reaction(prob, x, 0) - P11) <= 1e-6 * abs(P11)


@pytest.mark.parametrize("vol", ["log", "quadratic"])
@pytest.mark.parametrize("lam", [0.8, 1.3])
def test_equibiaxial(cube, cauchy, lam, vol):
    x, prob = cube
    mat = OgdenMaterial(C, M, K, vol)
    cons = symmetric_rollers(x) + [
        Constraint(np.flatnonzero(x[:, 0] == 1.0), (0,), lam - 1),
        Constraint(np.flatnonzero(x[:, 1] == 1.0), (1,), lam - 1)]
    sol = prob.solve(mat, cons, [], np.linspace(0.2, 1.0, 5))
    assert sol.status == "ok", sol.failure_reason
    l3 = brentq(lambda t: cauchy([lam, lam, t], C, M, K, vol)[2], 0.2, 3.0, xtol=1e-15)
    s = cauchy([lam, lam, l3], C, M, K, vol)
    P11 = s[0] * lam * l3
    np.testing.assert_allclose(1 + sol.displacement[-1][x[:, 2] == 1.0, 2], l3, rtol=1e-9)
    assert abs(face_reaction(prob, x, 0) - P11) <= 1e-6 * abs(P11)
    assert abs(face_reaction(prob, x, 1) - P11) <= 1e-6 * abs(P11)


@pytest.mark.parametrize("vol", ["log", "quadratic"])
def test_small_strain_shear_modulus(cube, vol):
    """Simple shear u = (g y, 0, 0) on the whole boundary: shear force on y = 1 per unit area
    -> mu g with mu = sum(c_k)/2, to O(g^2) (shear stress is odd in g)."""
    x, prob = cube
    c = (3e-3, 1e-3)
    mat = OgdenMaterial(c, (10.06, -3.0), 0.5, vol)
    g = 1e-5
    on_boundary = np.flatnonzero(np.any((x == 0.0) | (x == 1.0), axis=1))
    values = np.zeros((on_boundary.size, 3))
    values[:, 0] = g * x[on_boundary, 1]
    sol = prob.solve(mat, [Constraint(on_boundary, (0, 1, 2), values)], [], [1.0])
    assert sol.status == "ok", sol.failure_reason
    shear = prob.reaction(np.flatnonzero(x[:, 1] == 1.0))[0]
    assert abs(shear / g - sum(c) / 2) <= 1e-6 * sum(c) / 2
