"""The pseudo-elastic stiffness that moves the template's interior (liverreg.morph): one
tetrahedron against its hand-derived matrix, rigid motions free of force, the strain energy
of a uniform strain in closed form, the patch test, and the assembly with fixed nodes equal to
the plain COO assembly's blocks."""

import numpy as np
import pytest

from data_spec.geometry import signed_volumes
from liverreg.morph import ElasticAssembly, elastic_stiffness, element_stiffness, stiffened_move


def box_mesh(n: int = 3, h: float = 10.0):
    """A cube of n^3 hexahedra, each cut into 6 positive tetrahedra (Kuhn's split), nodes
    jiggled so that no cell is a right-angled copy of another."""
    g = np.arange(n + 1) * h
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    cells = []
    for corner in np.ndindex(n, n, n):
        for path in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
            at = np.array(corner)
            v = [idx[tuple(at)]]
            for axis in path:  # a monotone path from the cube's corner to the opposite one
                at[axis] += 1
                v.append(idx[tuple(at)])
            cells.append(v)
    cells = np.array(cells)
    rng = np.random.default_rng(0)
    inner = np.all((P > 0) & (P < n * h), axis=1)
    P[inner] += rng.uniform(-0.2 * h, 0.2 * h, (inner.sum(), 3))
    flip = signed_volumes(P, cells) < 0
    cells[flip] = cells[flip][:, [0, 2, 1, 3]]
    return P, cells, ~inner


def test_one_tetrahedron_has_its_hand_derived_stiffness():
    """The unit corner tetrahedron (0, e1, e2, e3), V = 1/6, E = 1, nu = 0.3:
    lam = 0.3 / (1.3 * 0.4) = 0.576923, mu = 1 / 2.6 = 0.384615, gradients g0 = (-1, -1, -1),
    g1 = e1, g2 = e2, g3 = e3. K_e[(a, i), (b, j)] = V (lam g_ai g_bj + mu g_aj g_bi +
    mu g_a.g_b delta_ij): node 1 x with node 1 x is V (lam + 2 mu) = 0.224359; node 1 x with
    node 2 y is V lam = 0.096154; node 1 y with node 2 x is V mu = 0.064103; node 0 x with
    node 0 x is V (lam + mu + 3 mu) = 0.352564."""
    P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    K = element_stiffness(P, np.array([[0, 1, 2, 3]]), np.ones(1))[0]
    assert K[3, 3] == pytest.approx(0.224359, abs=1e-6)
    assert K[3, 7] == pytest.approx(0.096154, abs=1e-6)
    assert K[4, 6] == pytest.approx(0.064103, abs=1e-6)
    assert K[0, 0] == pytest.approx(0.352564, abs=1e-6)
    np.testing.assert_allclose(K, K.T, atol=1e-15)


def test_rigid_motions_cost_nothing_and_a_uniform_strain_its_closed_form_energy():
    """K u = 0 for the 6 rigid motions of the whole mesh; u = eps x with a symmetric eps
    stores V_total (lam tr(eps)^2 / 2 + mu eps:eps) per unit Young's modulus, times E."""
    P, cells, _ = box_mesh()
    E = 2.5
    K = elastic_stiffness(P, cells, np.full(len(cells), E))
    rigid = [np.tile(e, (len(P), 1)) for e in np.eye(3)]
    rigid += [np.cross(w, P - P.mean(axis=0)) for w in np.eye(3)]
    for u in rigid:
        assert np.abs(K @ u.ravel()).max() < 1e-10 * np.abs(K).max() * np.abs(u).max()
    eps = np.array([[0.01, 0.003, -0.002], [0.003, -0.004, 0.005], [-0.002, 0.005, 0.002]])
    u = (P @ eps.T).ravel()
    nu = 0.3
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    volume = 30.0 ** 3
    energy = volume * (0.5 * lam * np.trace(eps) ** 2 + mu * np.sum(eps * eps))
    assert 0.5 * u @ (K @ u) == pytest.approx(energy, rel=1e-12)


def test_the_assembly_with_fixed_nodes_is_the_plain_assembly_and_passes_the_patch_test():
    """The free block and the free-fixed coupling equal the COO assembly's (moduli vary per
    cell, fixed nodes in a shuffled order); with a uniform modulus, the box's outer nodes moved
    by a linear field move every inner node by the same field (the patch test)."""
    P, cells, outer = box_mesh()
    rng = np.random.default_rng(1)
    E = rng.uniform(0.5, 2.0, len(cells))
    fixed = rng.permutation(np.flatnonzero(outer))
    asm = ElasticAssembly(len(P), cells, fixed)
    K_ff, coupling = asm.matrices(P, E)
    K = elastic_stiffness(P, cells, E)
    np.testing.assert_allclose(K_ff.toarray(), K[asm.free][:, asm.free].toarray(), atol=1e-12)
    du = rng.normal(size=asm.fixed.size)
    np.testing.assert_allclose(coupling(du), K[asm.free][:, asm.fixed] @ du, atol=1e-12)
    A = np.array([[0.02, -0.01, 0.005], [0.01, 0.03, 0.0], [-0.004, 0.002, -0.01]])
    moved = stiffened_move(P, cells, fixed, P[fixed] @ (np.eye(3) + A).T, steps=1)
    np.testing.assert_allclose(moved, P @ (np.eye(3) + A).T, atol=1e-10)


def test_the_unfolding_gives_a_stage_up_when_a_widened_patch_brings_no_fewer_folds(monkeypatch):
    """The relaxation's rounds against a scripted count of folded cells: it stops when none
    is left; it gives up 10 rounds after a widening of the patch (every 50 rounds) that brought
    no new fewest count, and goes on while a widening brings one; otherwise ``rounds`` end it."""
    from liverreg import morph

    P, cells, outer = box_mesh()
    m = morph.SurfaceMorph(P, cells, np.flatnonzero(outer))
    m.place = lambda boundary_points: m.points  # the counts below stand for the moves

    def rounds(script, **kw):
        counts = iter(script)

        def volumes(points, c):
            v = np.ones(len(c))
            v[:next(counts)] = -1.0
            return v

        monkeypatch.setattr(morph, "signed_volumes", volumes)
        return m.unfold(m.points[m.boundary], **kw)[1]

    assert rounds([3] * 5 + [0]) == 5
    assert rounds([3] * 5 + [2] * 200) == 60     # fewest at round 5: the widening at 50 fails
    assert rounds([3] * 55 + [2] * 200) == 110   # the widening at 50 helped; the one at 100 not
    assert rounds([3] * 200, patience=10**6) == 150
