"""The shape model a new liver is placed with (liverreg): the same registration and PCA as the
population it comes from, in numpy and scipy only. Synthetic "livers": a box mesh bent by
smooth, different warps (CPD needs no liver shape to be tested)."""

import numpy as np
import pytest

from data_spec.geometry import Geometry, box_mesh
from liverreg.cpd import build_population, project
from liverreg.morph import interpolation_matrix
from liverreg.shape_model import AREA_MARGIN, ShapeModel, nearest_convex_combination

N_POINTS = 150
SCHEDULE = ((2.0, 1.5, 1e-3), (0.6, 0.45, 1e-4))  # two stages: fast enough for a test


def warped(a: float, b: float, c: float) -> Geometry:
    g = box_mesh(5, (120.0, 80.0, 60.0))
    x = g.points - g.points.mean(0)
    p = x + np.stack([a * np.sin(x[:, 1] / 30), b * np.cos(x[:, 0] / 40),
                      c * np.sin(x[:, 0] / 50) + 0.05 * a * x[:, 2]], axis=1)
    # a grid has exact ties of distance, which farthest-point sampling breaks by rounding;
    # real surfaces have none
    p += np.random.default_rng([a + 10, b + 10, c + 10]).normal(0, 0.05, p.shape)
    return Geometry(points=p, cells=g.cells, surface_triangles=g.surface_triangles,
                    regions={"fixed": np.flatnonzero(g.points[:, 0] == 0)})


@pytest.fixture(scope="module")
def population():
    params = [(0, 0, 0), (6, 2, 3), (-4, 5, 1), (3, -5, 6), (-6, -2, -4), (2, 6, -5)]
    livers = [warped(*p) for p in params]
    pop = build_population(livers, 0, N_POINTS, SCHEDULE)
    M = livers[0]
    k = 3
    coeff = pop.coefficients[:, :k]
    sm = ShapeModel(template_points=M.points, template_cells=M.cells,
                    surface_triangles=M.surface_triangles, fixed_nodes=M.regions["fixed"],
                    mean=pop.mean, components=pop.components[:k],
                    coefficient_min=coeff.min(0), coefficient_max=coeff.max(0),
                    residuals=pop.registration_error, n_points=N_POINTS, schedule=SCHEDULE,
                    population_inverted=pop.inverted, population_coefficients=coeff)
    sm.population_fixed_area = sm.fixed_areas(pop.mean + pop.coefficients @ pop.components)
    return livers, pop, sm


def test_a_population_liver_gets_the_coefficients_the_population_gave_it(population):
    """One implementation on both sides: placing liver r (already in the population's frame)
    repeats the population's registration exactly, so its coefficients are its PCA
    coefficients and its residual the population's."""
    livers, pop, sm = population
    for r in (1, 4):
        g = livers[r]
        pl = sm.place(g.points, g.surface_triangles, center=False)
        np.testing.assert_allclose(pl.coefficients, pop.coefficients[r, :3], rtol=1e-8,
                                   atol=1e-8 * np.abs(pop.coefficients).max())
        assert pl.residual == pytest.approx(pop.registration_error[r], rel=1e-8)
        assert pl.inverted == pop.inverted[r]
        assert sm.warnings(pl) == []


def test_the_registered_template_lies_on_the_liver_and_centering_removes_position(population):
    livers, pop, sm = population
    g = livers[3]
    shift = np.array([130.0, -40.0, 75.0])  # another scanner's frame
    pl = sm.place(g.points + shift, g.surface_triangles)
    ref = sm.place(g.points, g.surface_triangles)
    # moved into the population's frame: the same placement wherever the file put the liver
    # (up to rounding, which CPD's stopping tolerances can turn into an extra iteration)
    np.testing.assert_allclose(pl.rotation, ref.rotation, atol=1e-6)
    np.testing.assert_allclose(pl.offset, ref.offset - ref.rotation @ shift, atol=1e-4)
    surf = sm.surface_nodes
    assert np.abs(pl.points - ref.points)[surf].max() < 0.1
    np.testing.assert_allclose(pl.coefficients, ref.coefficients,
                               atol=0.02 * np.abs(ref.coefficients).max())
    # the template moved onto liver 3 is within a fraction of the mesh spacing (24 mm)
    assert pl.residual < 2.0
    # coefficients reproduce the registered surface through the PCA (no truncation error
    # for a population member beyond the first 3 components' share)
    S = sm.template_points[sm.surface_nodes]
    d = (ref.points[sm.surface_nodes] - S).ravel()
    np.testing.assert_allclose(project(d, sm.mean, sm.components), ref.coefficients)


def test_a_liver_outside_the_population_is_named_with_its_numbers(population):
    livers, pop, sm = population
    g = livers[2]
    c = g.points.mean(0)
    big = c + 1.8 * (g.points - c)  # 1.8x larger: the template fits it less well, in mm
    pl = sm.place(big, g.surface_triangles)
    assert pl.residual > 1.5 * pop.registration_error.max()
    msgs = sm.warnings(pl)
    assert any(m.startswith("registration residual") and f"{pl.residual:.2f} mm" in m
               for m in msgs)
    # its fixed face (x = 0 of the box: 80 x 60 mm on the unwarped liver 0, the template) is
    # 1.8^2 = 3.24 times liver 2's, beyond the population's largest, and is named with the
    # numbers
    A = sm.population_fixed_area
    assert A[0] == pytest.approx(80 * 60, rel=1e-3)
    a = sm.fixed_area(pl.points)
    assert a == pytest.approx(1.8 ** 2 * A[2], rel=0.1)
    assert a > AREA_MARGIN * A.max()
    assert any(m.startswith(f"the fixed region covers {a:.0f} mm^2") and
               f"{A.min():.0f} .. {A.max():.0f} mm^2" in m for m in msgs), msgs
    bent = warped(24, 0, 0)  # four times the population's largest bend
    # in the population's frame as declared (a box is nearly symmetric: a free rigid fit may
    # turn the bend into a tilt)
    msgs = sm.warnings(sm.place(bent.points, bent.surface_triangles, frame="population"))
    assert any("shape coefficients outside the population's range" in m for m in msgs), msgs


def test_save_and_load_give_the_same_model(population, tmp_path):
    _, _, sm = population
    sm.save(tmp_path / "sm.npz")
    back = ShapeModel.load(tmp_path / "sm.npz")
    for name in ("template_points", "template_cells", "mean", "components", "schedule",
                 "coefficient_min", "loadable_nodes", "population_coefficients"):
        np.testing.assert_array_equal(getattr(back, name), getattr(sm, name))
    np.testing.assert_array_equal(back.population_fixed_area, sm.population_fixed_area)
    assert back.n_points == sm.n_points
    # a file written before the population's coefficients were kept still loads; the rules
    # that need them fall back to the ranges, and say so
    with np.load(tmp_path / "sm.npz") as z:
        old = {k: z[k] for k in z.files
               if k not in ("population_coefficients", "population_fixed_area")}
    np.savez(tmp_path / "old.npz", **old)
    older = ShapeModel.load(tmp_path / "old.npz")
    assert older.population_coefficients.shape == (0, sm.n_components)
    assert older.population_fixed_area.size == 0  # and no fixed-region warning from it
    far = 3 * sm.coefficient_max
    told, rule = older.shape_told(far, "hull")
    assert rule == "range"
    np.testing.assert_allclose(told, sm.coefficient_max)
    (tmp_path / "bad.npz").write_bytes(b"not an npz")
    with pytest.raises(ValueError, match="bad.npz: not a readable shape model"):
        ShapeModel.load(tmp_path / "bad.npz")


def test_the_nearest_convex_combination_by_hand():
    """Corners of the unit square: a point beside it goes to the nearest edge, a point beyond
    a corner to the corner, a point inside stays; a point above a triangle in 3-D drops onto
    it."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    for x, want in (([2.0, 0.5], [1.0, 0.5]), ([2.0, 2.0], [1.0, 1.0]),
                    ([0.3, 0.6], [0.3, 0.6]), ([-1.0, 0.25], [0.0, 0.25])):
        np.testing.assert_allclose(nearest_convex_combination(square, np.array(x)), want,
                                   atol=1e-7)
    tri = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 4.0, 0.0]])
    np.testing.assert_allclose(nearest_convex_combination(tri, np.array([1.0, 1.0, 5.0])),
                               [1.0, 1.0, 0.0], atol=1e-7)


def test_the_shape_a_network_is_told(population):
    """A population liver, and one between them, is told its own shape by every rule; a liver
    beyond the population is told one inside it: clipped to the ranges, scaled back to the
    population's largest Mahalanobis radius along the same direction, or the nearest convex
    combination of the population's livers (no farther than any of them, and inside the
    largest radius). ``outside`` tells that mix also to a liver inside the radius with one
    coefficient beyond the population's range, which ``hull`` leaves alone."""
    _, _, sm = population
    C = sm.population_coefficients
    std = C.std(axis=0)
    for c in [*C, 0.5 * (C[1] + C[3])]:
        for rule in ("own", "range", "radius", "hull", "outside"):
            told, used = sm.shape_told(c, rule)
            assert used == "own"
            np.testing.assert_array_equal(told, c)
    far = 2.5 * C[1] - 1.5 * C[2]
    radius, used = sm.shape_told(far, "radius")
    assert used == "radius"
    r = np.linalg.norm(radius / std)
    assert r == pytest.approx(np.linalg.norm(C / std, axis=1).max(), rel=1e-9)
    np.testing.assert_allclose(radius / np.linalg.norm(radius), far / np.linalg.norm(far))
    clipped, _ = sm.shape_told(far, "range")
    assert np.all(clipped >= sm.coefficient_min) and np.all(clipped <= sm.coefficient_max)
    hull, _ = sm.shape_told(far, "hull")
    d_hull = np.linalg.norm((hull - far) / std)
    assert d_hull <= np.linalg.norm((C - far) / std, axis=1).min() + 1e-9
    # the hull lies inside the ball of the largest radius, whose nearest point is the scaled
    # one: the hull is never nearer
    assert d_hull >= np.linalg.norm((radius - far) / std) - 1e-9
    assert np.linalg.norm(hull / std) <= r + 1e-9
    np.testing.assert_array_equal(sm.shape_told(far, "own")[0], far)
    assert sm.shape_told(far, "hull")[1] == "hull" and sm.shape_told(far, "range")[1] == "range"
    np.testing.assert_allclose(sm.shape_told(far, "outside")[0], hull)
    # inside the largest radius, one coefficient 10 % of its range beyond the population's
    lo, hi = sm.coefficient_min, sm.coefficient_max
    j = int(np.argmax((hi - lo) / std))  # the widest range in standard deviations
    odd = C.mean(axis=0)
    odd[j] = hi[j] + 0.1 * (hi[j] - lo[j])
    assert np.linalg.norm(odd / std) < np.linalg.norm(C / std, axis=1).max()
    assert sm.outside_range(odd).tolist() == [j]
    np.testing.assert_array_equal(sm.shape_told(odd, "hull")[0], odd)
    mix, used = sm.shape_told(odd, "outside")
    assert used == "outside"
    # a convex combination of the livers lies inside every range
    assert np.all((mix >= lo - 1e-6 * (hi - lo)) & (mix <= hi + 1e-6 * (hi - lo)))
    np.testing.assert_allclose(mix, sm.nearest_mix(odd))
    with pytest.raises(ValueError, match="shape rule 'nearest': expected one of own, range"):
        sm.shape_told(far, "nearest")


def test_interpolation_is_exact_for_linear_fields_and_at_the_nodes():
    """Barycentric interpolation reproduces a linear field inside the hull and the node
    values at the nodes; outside the hull it takes the nearest node's value."""
    rng = np.random.default_rng(0)
    nodes = rng.uniform(-50, 50, size=(300, 3))
    field = nodes @ np.array([0.3, -0.2, 0.1]) + 2.0
    inside = rng.uniform(-20, 20, size=(50, 3))
    W = interpolation_matrix(nodes, np.vstack([inside, nodes[:5], [[500.0, 0, 0]]]))
    got = W @ field
    np.testing.assert_allclose(got[:50], inside @ np.array([0.3, -0.2, 0.1]) + 2.0, rtol=1e-9)
    np.testing.assert_allclose(got[50:55], field[:5], rtol=1e-9)
    nearest = np.argmin(np.linalg.norm(nodes - [500.0, 0, 0], axis=1))
    assert got[55] == pytest.approx(field[nearest])
