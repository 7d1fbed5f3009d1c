"""Stability at the extremes, each with a definite expected outcome (``make test-extremes``).

Every case of ``cases.extremes()`` (the corners of every shipped scene's sampled ranges,
forces 5x/10x nominal, next to the fixed region, K/mu from 10 to 10000, two opposite forces on
neighbouring nodes, zero force, the whole load in one step) is expected to converge through all
its load steps on the phantom and on the real liver at 16 mm (measured; docs/extremes.md), and
is checked beyond "it converged": finite values, global equilibrium (the fixed region carries
the applied load), positive work of the loads, and the physics between cases (stiffening with
force, incompressibility with K/mu, path independence of hyperelasticity). A sliver-heavy mesh
reproduces a homogeneous state exactly; tangled meshes are refused before any work
(tests/fem_sim/test_geometry.py, test_generate.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.extremes.cases import (
    applied_force,
    extremes,
    liver,
    livers,
    loads,
    simulate,
    tools,
)

pytestmark = pytest.mark.extremes
CASES = {c.name: c for c in extremes()}


@pytest.fixture(scope="module")
def outcome():
    """Solve each case once: name -> (Solution, reaction on the fixed region)."""
    done = {}

    def get(name):
        if name not in done:
            case = CASES[name]
            prob, sol = simulate(case)
            done[name] = (sol, sol.reaction[-1, 0] if sol.n_done else None)
        return done[name]

    return get


@pytest.mark.parametrize("name", list(CASES))
def test_converges_with_finite_balanced_answer(name, outcome):
    case = CASES[name]
    sol, reaction = outcome(name)
    assert sol.status == "ok", sol.failure_reason
    assert sol.n_done == len(case.fractions)
    assert np.isfinite(sol.displacement).all()
    applied = applied_force(case, sol)
    # global equilibrium: the fixed region carries the whole load (the tools' forces too)
    np.testing.assert_allclose(reaction, -applied, atol=1e-6 * max(1.0, np.abs(applied).max()))
    u = sol.displacement[-1]
    g = liver(case.liver)[0]
    work = sum(float(np.sum(ld.forces * u[ld.nodes])) if hasattr(ld, "forces") else   # vertices
               float(ld.force @ u[np.argmin(np.linalg.norm(g.points - ld.centre, axis=1))])
               for ld in loads(case))
    work += sum(float(f @ d) for f, (_, d) in zip(sol.reaction[-1, 1:], tools(case)))
    if "zero" in case.tags:
        assert np.all(u == 0.0) and sum(sol.newton_iterations) == 0
    else:
        assert work > 0.0  # the loads do positive work on a stable body


@pytest.mark.parametrize("liver_name", livers())
def test_physics_between_extremes(liver_name, outcome):
    def tip(name):
        sol, _ = outcome(f"{liver_name}-{name}")
        return sol.displacement[-1]

    far = loads(CASES[f"{liver_name}-force-5x"])[0].nodes[0]
    u1 = np.linalg.norm(tip("scene1-P1-c0.0041-m10.06-1x0.4N-away" if liver_name == "sofa"
                            else "scene1-P2-c0.0041-m10.06-1x0.4N-away")[far])
    u5, u10 = (np.linalg.norm(tip(f"force-{k}x")[far]) for k in (5, 10))
    # Ogden m = 10: the liver stiffens under stretch, so 2x the force gives less than 2x
    assert u1 < u5 < u10 < 2.0 * u5
    # more nearly incompressible: smaller displacement (P1 also locks: see docs/extremes.md)
    ks = [np.linalg.norm(tip(f"K_over_mu-{k:g}")[far]) for k in (10, 100, 1000, 10000)]
    assert all(a > b for a, b in zip(ks, ks[1:])), ks
    # hyperelastic: the answer does not depend on the load path (1 step with cut-backs or 10)
    one, ten = tip("one-step-5x"), tip("force-5x")
    assert np.abs(one - ten).max() <= 1e-6 * np.abs(ten).max()


def test_sliver_heavy_mesh_reproduces_a_homogeneous_state():
    """P1 reproduces linear displacement fields exactly, whatever the element shapes: on a
    cube whose middle layers are squeezed to 1/500 of their width (half the tetrahedra with
    mean-ratio quality < 0.05), uniaxial stretch gives the same displacement and force as on
    the regular cube."""
    from mpi4py import MPI

    from fem_sim import Constraint, OgdenMaterial, OgdenProblem
    from fem_sim.geometry.quality import mean_ratio, mesh_problems
    from tests.fixtures import box_mesh

    g = box_mesh(4)
    x = g.points
    shaken = x.copy()
    shaken[:, 2] = np.interp(x[:, 2], [0, 0.25, 0.5, 0.75, 1], [0, 0.4995, 0.5, 0.5005, 1])
    q = mean_ratio(shaken, g.cells)
    assert np.sum(q < 0.05) >= g.cells.shape[0] // 2 and mesh_problems(shaken, g.cells) == []
    mat = OgdenMaterial((4.1e-3,), (10.06,), 0.41)
    out = []
    for pts in (x, shaken):
        prob = OgdenProblem(MPI.COMM_WORLD, pts, g.cells, settings={"rtol": 1e-12})
        cons = [Constraint(np.flatnonzero(pts[:, i] == 0.0), (i,), 0.0) for i in range(3)]
        cons.append(Constraint(np.flatnonzero(pts[:, 0] == 1.0), (0,), 0.3))
        sol = prob.solve(mat, cons, [], [0.5, 1.0])
        assert sol.status == "ok", sol.failure_reason
        corner = int(np.flatnonzero(np.all(pts == 1.0, axis=1))[0])
        out.append((sol.displacement[-1][corner],
                    prob.reaction(np.flatnonzero(pts[:, 0] == 1.0))[0]))
    np.testing.assert_allclose(out[1][0], out[0][0], rtol=1e-8)
    assert out[1][1] == pytest.approx(out[0][1], rel=1e-8)


@pytest.mark.parametrize("name", [n for n, c in CASES.items() if "grasp" in c.tags])
def test_a_grasp_moves_its_patch_and_pulls_harder_the_further_it_goes(name, outcome):
    """A 40 mm grasp on a CT liver: the patch follows the tool at every step, and the tool's
    force along its pull grows with the pull and faster than in proportion (the Ogden liver
    stiffens under stretch: m = 10)."""
    case = CASES[name]
    sol, _ = outcome(name)
    (patch, d), = tools(case)
    lam = np.asarray(case.fractions)
    for k in range(sol.n_done):
        np.testing.assert_allclose(sol.displacement[k][patch],
                                   np.broadcast_to(lam[k] * d, (patch.size, 3)), atol=1e-9)
    along = sol.reaction[:, 1] @ (d / np.linalg.norm(d))
    assert np.all(np.diff(along) > 0) and along[0] > 0
    assert along[-1] / lam[-1] > 1.2 * along[0] / lam[0]   # secant stiffness rises by a fifth
