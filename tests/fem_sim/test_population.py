"""Scene 4's shape parametrisation: CPD recovers known deformations; PCA coefficients,
reconstructions and their IoU behave; the scene pipeline attaches and caches coefficients."""

import numpy as np
import pytest

from fem_sim.geometry.masks import voxelize_surface
from fem_sim.geometry.phantom import make_phantom
from fem_sim.geometry.population import (
    PLAIN,
    STAGED,
    attach_shape_coefficients,
    build_population,
    chamfer,
    cpd_nonrigid,
    farthest_points,
    overlap,
    report,
    surface_points,
    surface_samples,
)


def warp(p):
    """A smooth, large, non-affine deformation (mm)."""
    c = p - p.mean(0)
    return p + np.stack([8 * np.sin(c[:, 1] / 40), 6 * np.cos(c[:, 0] / 50),
                         0.05 * c[:, 0] + 4 * np.sin(c[:, 2] / 30)], axis=1)


@pytest.fixture(scope="module")
def phantom():
    return make_phantom(0, 10.0)


def test_farthest_points_spread_out():
    rng = np.random.default_rng(0)
    pts = rng.uniform(size=(2000, 3))
    idx = farthest_points(pts, 50)
    assert np.unique(idx).size == 50
    d = np.linalg.norm(pts[idx][:, None] - pts[idx][None], axis=2) + np.eye(50)
    assert d.min() > 0.1  # random 50 points would come much closer


@pytest.mark.slow
def test_cpd_recovers_a_known_smooth_deformation(phantom):
    """Register the phantom's surface onto its warped copy: the moved template surface lies
    on the warped surface (symmetric mean distance between the densely sampled surfaces; a
    surface registration cannot recover sliding along the surface, so no point-to-point
    error). Both staged and plain CPD must remove most of the initial distance."""
    S = phantom.points[phantom.surface_nodes]
    target = warp(S)
    dense_t, dense_s = warp(surface_points(phantom)), surface_points(phantom)
    X = target[farthest_points(target, 800, seed=1)]
    Y = S[farthest_points(S, 800, seed=2)]
    before = chamfer(dense_s, dense_t)
    errs = {}
    for name, sched in (("staged", STAGED), ("plain", PLAIN)):
        errs[name] = chamfer(cpd_nonrigid(X, Y, sched).transform(dense_s), dense_t)
    assert before > 3.0
    assert max(errs.values()) < 0.35 * before, (before, errs)


def test_cpd_m_step_solves_the_textbook_equation():
    """The symmetric (Cholesky) M-step gives the W of Myronenko & Song's own equation,
    (diag(P1) G + c I) W = PX - diag(P1) Y, solved by LU, including template points no
    target claims (P1 = 0, PX = 0) and posteriors spanning 1e-12 to 1."""
    from liverreg.cpd import _m_step, _sqdist

    rng = np.random.default_rng(3)
    Y, X = rng.normal(size=(80, 3)), rng.normal(size=(90, 3))
    G = np.exp(-_sqdist(Y, Y) / (2.0 * 0.6**2))
    P = rng.uniform(size=(80, 90)) * 10.0 ** rng.uniform(-12, 0, size=(80, 1))
    P[[3, 41]] = 0.0
    P1, PX, c = P.sum(1), P @ X, 0.45 * 0.02
    want = np.linalg.solve(P1[:, None] * G + c * np.eye(80), PX - P1[:, None] * Y)
    got = _m_step(G, P1, PX, Y, c)
    assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()
    assert np.all(got[[3, 41]] == 0.0)


def test_voxelised_surface_matches_the_tetrahedra(phantom):
    from fem_sim.geometry.phantom import mesh_volume

    mask, _ = voxelize_surface(phantom.points, phantom.surface_triangles, 1.0)
    assert mask.sum() == pytest.approx(mesh_volume(phantom), rel=0.01)
    iou, dice = overlap(phantom.points, phantom.surface_triangles, phantom.points,
                        phantom.surface_triangles)
    assert iou == 1.0 and dice == 1.0


@pytest.fixture(scope="module")
def population():
    livers = [make_phantom(1000 + i, 14.0) for i in range(5)]
    return livers, build_population(livers, n_points=300)


def test_pca_of_a_small_population(population):
    livers, pop = population
    R = len(livers)
    assert pop.coefficients.shape == (R, R)
    ev = np.cumsum(pop.explained_variance_ratio)
    assert ev[R - 2] == pytest.approx(1.0, abs=1e-9)  # R livers span R - 1 directions
    # all components rebuild each registered template exactly
    for r in range(R):
        np.testing.assert_allclose(pop.reconstruct(r, R - 1).ravel(),
                                   (pop.template.points[pop.template.surface_nodes].ravel()
                                    + pop.displacements[r]), atol=1e-8)
    # the template registers onto itself with (nearly) no displacement
    assert np.abs(pop.displacements[0]).max() < 1.0
    assert np.all(pop.registration_error < 3.5)
    rows = report(pop, livers, [1, R - 1])
    assert rows[1]["iou_mean"] > 0.95 and rows[1]["iou_mean"] >= rows[0]["iou_mean"]
    assert 0 < rows[0]["explained_variance"] < rows[1]["explained_variance"]


def test_scene_population_gets_cached_coefficients(tmp_path, population):
    livers, _ = population
    cache = tmp_path / "population.npz"
    pop = attach_shape_coefficients(livers, 3, cache=cache, n_points=300)
    assert pop is not None and cache.exists()
    first = [g.shape_coefficients.copy() for g in livers]
    assert all(c.shape == (3,) for c in first)
    for g in livers:
        g.shape_coefficients = None
    assert attach_shape_coefficients(livers, 3, cache=cache) is None  # from the cache
    for g, c in zip(livers, first):
        np.testing.assert_array_equal(g.shape_coefficients, c)
    with pytest.raises(ValueError, match="needs at least 6 livers"):
        attach_shape_coefficients(livers, 5)


def test_a_grown_population_registers_only_its_new_livers(tmp_path, population, monkeypatch):
    """The cache of 4 livers serves the registrations of those 4 in a population of 5 (the
    PCA is new), exactly as registering them again would; another sample count reuses none.
    """
    import liverreg.cpd as cpd

    livers, pop = population
    cache = tmp_path / "population.npz"
    attach_shape_coefficients(livers[:4], 2, cache=cache, n_points=300)
    calls, register = [], cpd.register
    monkeypatch.setattr(cpd, "register", lambda *a, **k: calls.append(1) or register(*a, **k))
    grown = attach_shape_coefficients(livers, 3, cache=cache, n_points=300)
    assert len(calls) == 1
    np.testing.assert_allclose(grown.displacements, pop.displacements, atol=1e-8)
    np.testing.assert_allclose(grown.registration_error, pop.registration_error)
    calls.clear()
    attach_shape_coefficients(livers[:4], 2, cache=cache, n_points=250)
    assert len(calls) == 4


def test_surface_points_sample_the_triangles(phantom):
    pts = surface_points(phantom)
    assert pts.shape[0] > 5 * phantom.surface_nodes.size
    assert chamfer(surface_samples(phantom, 200), pts) < 6.0


def test_population_command_writes_geometries_and_report(tmp_path):
    """`python3 -m fem_sim population`: geometry files with coefficients, the npz, and the
    Markdown/JSON/PNG report (rows for n = 1..R-1); a non-population scene exits 2."""
    import json

    from data_spec import read_geometry
    from fem_sim.__main__ import main

    scene = tmp_path / "pop.toml"
    scene.write_text('schema_version = 1\n[scene]\nname = "pop_test"\nn_simulations = 4\n'
                     '[geometry]\nsource = "population"\npopulation_size = 4\n'
                     'pca_components = 2\nmesh_size = 20.0\n'
                     '[material]\nc = [4.1e-3]\nm = [10.06]\n[loads]\nmagnitude = 0.4\n')
    out = tmp_path / "out"
    assert main(["population", str(scene), "--out", str(out), "--no-progress",
                 "--compare-plain", "1"]) == 0
    geos = sorted((out / "geometry").glob("*.h5"))
    assert len(geos) == 4
    assert all(read_geometry(p).shape_coefficients.shape == (2,) for p in geos)
    rows = json.loads((out / "population.json").read_text())["rows"]
    assert [r["n"] for r in rows] == [1, 2, 3]
    assert (out / "population.png").stat().st_size > 0
    assert "Staged vs plain" in (out / "population.md").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(scene.read_text().replace('source = "population"\npopulation_size = 4\n'
                                             'pca_components = 2\n', 'source = "phantom"\n'))
    assert main(["population", str(bad), "--out", str(out)]) == 2
