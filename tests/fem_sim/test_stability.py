"""Extremes with a definite expected outcome: 5x the nominal force on the softest material of
scene 3's range, and a force next to the fixed region at K/mu = 1000. Each must converge through
every load step (cut-backs allowed) and give a physically right answer, checked beyond "it
converged": direction, strain stiffening, global equilibrium, near-incompressibility."""

import numpy as np
import pytest
from mpi4py import MPI

from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
from fem_sim.geometry.phantom import make_phantom

FRACTIONS = np.linspace(0.1, 1.0, 10)


@pytest.fixture(scope="module")
def liver():
    return make_phantom(0, 20.0)


def _converged(sol):
    assert sol.status == "ok", sol.failure_reason
    assert sol.n_done == FRACTIONS.size
    assert np.isfinite(sol.displacement).all()


def _volume(points, cells):
    e = points[cells[:, 1:]] - points[cells[:, :1]]
    return np.linalg.det(e).sum() / 6.0


@pytest.fixture(scope="module")
def soft_tip(liver):
    """Tip displacement per step under 2 N (5x nominal) for c1 = 2e-3 MPa (scene 3's
    minimum) and m = 6 and 14."""
    tip = int(np.argmax(liver.points[:, 0]))
    out = {}
    for m in (6.0, 14.0):
        soft = OgdenMaterial((2.0e-3,), (m,), 200 * 1.0e-3)
        prob = OgdenProblem(MPI.COMM_WORLD, liver.points, liver.cells)
        sol = prob.solve(soft, [Constraint(liver.regions["vena_cava"])],
                         [NodalLoad([tip], [[0.0, 0.0, -2.0]])], FRACTIONS)
        _converged(sol)
        out[m] = sol.displacement[:, tip]
    return out


@pytest.mark.parametrize("m", [6.0, 14.0])
def test_five_times_force_on_softest_material_converges_along_the_force(soft_tip, m):
    u = soft_tip[m]
    assert u[-1, 2] < -20.0  # a large deformation (tens of mm), downwards like the force
    assert abs(u[-1, 2]) > np.abs(u[-1, :2]).max()
    assert np.all(np.diff(u[:, 2]) < 0)  # the tip goes further down at every load step


def test_larger_ogden_exponent_stiffens_at_large_strain(soft_tip):
    """Same initial shear modulus (c1/2), but m = 14 stiffens faster with stretch than m = 6:
    at 5x the nominal force its tip moves less; at the first step (10 %, moderate strain)
    both are closer together than at the last."""
    u6, u14 = np.abs(soft_tip[6.0][:, 2]), np.abs(soft_tip[14.0][:, 2])
    assert u14[-1] < 0.9 * u6[-1]
    assert u14[0] / u6[0] > u14[-1] / u6[-1]


def test_force_next_to_the_fixed_region_at_high_bulk_ratio(liver):
    """K/mu = 1000, 2 N on the free surface node closest to the fixed region: converges; the
    fixed region takes the whole load (reaction = -force) and the volume is kept to
    ~1/(K/mu) of the strain."""
    fixed = liver.regions["vena_cava"]
    surf = np.setdiff1d(liver.surface_nodes, fixed)
    d = np.linalg.norm(liver.points[surf][:, None] - liver.points[fixed][None], axis=2).min(1)
    near = int(surf[np.argmin(d)])
    mat = OgdenMaterial((4.1e-3,), (10.06,), 1000 * 4.1e-3 / 2)  # K/mu = 1000
    prob = OgdenProblem(MPI.COMM_WORLD, liver.points, liver.cells)
    force = np.array([0.0, 0.0, 2.0])
    sol = prob.solve(mat, [Constraint(fixed)], [NodalLoad([near], [force])], FRACTIONS)
    _converged(sol)
    u = sol.displacement[-1]
    assert u[near, 2] > 0.1 and u[near, 2] > np.abs(u[near, :2]).max()
    np.testing.assert_allclose(prob.reaction(fixed), -force, atol=1e-6 * 2.0)
    v0 = _volume(liver.points, liver.cells)
    dv = _volume(liver.points + u, liver.cells) - v0
    assert abs(dv) / v0 < 1e-5, dv / v0  # measured 1.4e-6; K/mu = 10 gives 4.2e-5



def test_an_attempt_that_stalls_is_given_up_at_stall_iterations(monkeypatch):
    """Newton steps that only halve |R| (the slow phase): with stall_iterations = 5 the
    attempt ends at the 5th step with a StepFailure that says so; with 0 it goes on to
    max_iterations; one that has fallen below 1e-3 of its start by then goes on."""
    from fem_sim.solver.newton import STALL_FRACTION, NewtonSolver, _Attempt, is_stalled
    from fem_sim.solver.results import StepFailure
    from fem_sim.solver.settings import SolverSettings

    def newton(rate):
        def step(self, a, first_order_start):
            a.it, a.r = a.it + 1, a.r * rate
            return False
        return step

    def attempt(self, lam, history):
        self.start_residual = 1.0
        return _Attempt(lam=lam, r=1.0, gap=0.0, tol=0.0, scale=1.0, gap_tol=1.0,
                        history=history)

    monkeypatch.setattr(NewtonSolver, "_start", attempt)
    for limit, rate, expected in ((5, 0.5, "stalled"), (0, 0.5, "did not converge in 25"),
                                  (5, 0.1, "did not converge in 25")):
        monkeypatch.setattr(NewtonSolver, "_newton_step", newton(rate))
        solver = NewtonSolver.__new__(NewtonSolver)
        solver.settings = SolverSettings(stall_iterations=limit, chord_contraction=0.0)
        with pytest.raises(StepFailure, match=expected):
            solver.solve(0.5, [], False)
        assert solver.attempt_iterations == (5 if expected == "stalled" else 25)
    assert not is_stalled(5, 1.0, 1.0, 0) and not is_stalled(4, 1.0, 1.0, 5)
    assert is_stalled(5, 2 * STALL_FRACTION, 1.0, 5)
