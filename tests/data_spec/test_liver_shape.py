"""data_spec.liver_shape: the figures a surface is judged a liver by, by hand (issue 81: a
cube and a slab were meshed as livers without a word)."""

import numpy as np
import pytest

from data_spec.liver_shape import LIVER_RANGE, shape_figures, surface_volume_ml, unlike_a_liver

CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
QUADS = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
TRIS = np.array([(a, b, c) for a, b, c, _ in QUADS] + [(a, c, d) for a, _, c, d in QUADS])


def test_a_box_by_hand():
    """A 300 x 200 x 100 mm box: 6 L, its principal extents its sides, filling its box."""
    box = CORNERS * [300.0, 200.0, 100.0]
    assert surface_volume_ml(box, TRIS) == pytest.approx(6000.0)
    assert surface_volume_ml(box, TRIS[:, ::-1]) == pytest.approx(6000.0)   # either facing
    f = shape_figures(box, 6000.0)
    assert [f["extent_1_mm"], f["extent_2_mm"], f["extent_3_mm"]] == pytest.approx(
        [300.0, 200.0, 100.0])
    assert f["fill"] == pytest.approx(1.0)
    said = unlike_a_liver(box, 6000.0, "box.obj")
    # 6 L and a fill of 1 are beyond 1.5 times the livers' largest; its extents are not
    assert said.startswith("box.obj: not shaped like a liver: volume_ml 6e+03")
    assert "fill 1" in said and "extent" not in said


def test_the_range_is_the_livers_and_a_liver_sized_ellipsoid_passes():
    """An ellipsoid of semi-axes 110, 80, 60 mm (2.2 L, fill pi/6): inside every range."""
    rng = np.random.default_rng(0)
    d = rng.normal(size=(4000, 3))
    pts = d / np.linalg.norm(d, axis=1, keepdims=True) * [110.0, 80.0, 60.0]
    ml = 4.0 / 3.0 * np.pi * 110 * 80 * 60 / 1e3
    assert unlike_a_liver(pts, ml, "ellipsoid") is None
    assert all(lo < hi for lo, hi in LIVER_RANGE.values())
