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


def test_a_region_grows_by_rings_of_surface_neighbours_to_the_area_asked():
    """The box's x = 0 face (15 mm^2) asked for 10 mm^2 stays as it is (0 rings); asked for
    20, one ring adds the surface nodes next to it on the four sides around (a strip 1 mm
    wide, the mesh's spacing along x, around a 2 x 3 x 5 box's face: 2 (3 + 5) = 16 mm^2 more,
    31 in all), all on the surface and none on the far face."""
    from data_spec.geometry import grown_region

    g = box_mesh(2, size=(2.0, 3.0, 5.0))
    face = g.regions["x0"]
    same, rings = grown_region(g.points, g.surface_triangles, face, 10.0)
    assert rings == 0 and np.array_equal(same, np.unique(face))
    more, rings = grown_region(g.points, g.surface_triangles, face, 20.0)
    assert rings == 1 and np.all(np.isin(face, more))
    assert np.isclose(region_area(g.points, g.surface_triangles, more), 31.0)
    assert np.all(np.isin(more, g.surface_nodes)) and g.points[more, 0].max() == 1.0
