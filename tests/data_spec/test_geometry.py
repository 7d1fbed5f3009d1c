"""Geometry helpers of the contract, checked against values worked out by hand on a box."""

import numpy as np

from data_spec.geometry import box_mesh, region_area


def test_region_area_counts_the_triangles_whose_corners_are_all_in_the_region():
    """A 2 x 3 x 5 mm box: its x = 0 face is 3 x 5 = 15 mm^2; a triangle with one corner off
    the face is not counted, so one node more outside it changes nothing, and one of the
    face's nodes less loses the triangles around it."""
    g = box_mesh(2, size=(2.0, 3.0, 5.0))
    face = g.regions["x0"]
    assert np.isclose(region_area(g.points, g.surface_triangles, face), 15.0)
    inner = int(np.flatnonzero(g.points[:, 0] > 1.5)[0])
    assert np.isclose(region_area(g.points, g.surface_triangles, np.append(face, inner)), 15.0)
    assert region_area(g.points, g.surface_triangles, face[1:]) < 15.0
    assert region_area(g.points, g.surface_triangles, np.array([], dtype=int)) == 0.0
    # stretched 2x along y: the face (in the y-z plane) doubles
    g.points[:, 1] *= 2.0
    assert np.isclose(region_area(g.points, g.surface_triangles, face), 30.0)
