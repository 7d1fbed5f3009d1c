"""The liver drawing shared by fem_sim's summary, make docs and the surrogate's viewer: the
compact surface, its outward normals, the force-arrow rule, and off-screen renders that show
something and change with the field.
"""

import sys

import numpy as np
import pytest

from liverviz.pictures import Panel, Surface, arrow_segments, render_panels, write_gif
from tests.fixtures import box_mesh


@pytest.fixture(scope="module")
def box():
    g = box_mesh(3, (30.0, 20.0, 10.0))
    return g, Surface.from_mesh(g.points, g.surface_triangles, g.regions["x0"])


def test_surface_is_compact_and_keeps_the_fixed_nodes(box):
    g, s = box
    # A 3^3 box has 4^3 = 64 nodes, of which the 2^3 = 8 inner ones are not on the surface.
    assert s.nodes.size == 64 - 8
    assert np.array_equal(s.points, g.points[s.nodes])
    assert np.array_equal(s.nodes[s.triangles], g.surface_triangles)
    assert np.array_equal(np.sort(s.nodes[s.fixed]), np.sort(g.regions["x0"]))
    assert np.array_equal(s.local(s.nodes), np.arange(s.nodes.size))
    inner = np.setdiff1d(np.arange(g.n_nodes), s.nodes)
    assert np.all(s.local(inner) == -1)


def test_vertex_normals_point_out_of_the_box(box):
    g, s = box
    n = s.normals()
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    outward = s.points - g.points.mean(axis=0)
    assert np.all(np.sum(n * outward, axis=1) > 0)
    # The centre of the x = 30 face has the normal +x exactly (all its triangles are in-plane).
    mid = np.flatnonzero(np.isclose(s.points[:, 0], 30.0) & (s.points[:, 1] % 20 != 0)
                         & (s.points[:, 2] % 10 != 0))
    assert mid.size == 4  # the face's interior: a 2 x 2 grid of nodes
    assert np.allclose(n[mid], [1.0, 0.0, 0.0])


def test_arrows_touch_the_surface_and_scale_with_the_force():
    anchor, normal = np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, 1.0])
    # Pushing into the surface (against the normal): the arrow ends at the node.
    tail, vec = arrow_segments(anchor, [0.0, 0.0, -0.2], normal, length=10.0, f_ref=0.4)
    assert np.allclose(vec, [[0.0, 0.0, -5.0]])  # 10 mm * 0.2 / 0.4
    assert np.allclose(tail + vec, anchor)
    # Pulling: the arrow starts at the node.
    tail, vec = arrow_segments(anchor, [0.4, 0.0, 0.0], normal, length=10.0, f_ref=0.4)
    assert np.allclose(tail, anchor) and np.allclose(vec, [[10.0, 0.0, 0.0]])
    # Forces far above the reference are drawn at most 1.5 lengths long.
    _, vec = arrow_segments(anchor, [0.0, 40.0, 0.0], normal, length=10.0, f_ref=0.4)
    assert np.allclose(vec, [[0.0, 15.0, 0.0]])


def _liver_pixels(png):
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    return img, np.any(np.abs(img - 255) > 30, axis=2)  # not the white background


@pytest.fixture()
def renderer():
    """VTK must not render beside dolfinx (liverviz.pictures.pyvista says why): in the
    solver's test process these renders run in tests/fem_sim/test_summary_pictures.py, in a
    subprocess; here they run in the trainer's test process.
    """
    if "dolfinx" in sys.modules:
        pytest.skip("dolfinx is loaded in this test process: rendered in a subprocess by "
                    "tests/fem_sim/test_summary_pictures.py instead")


def test_off_screen_renders_show_the_liver_and_change_with_the_field(box, tmp_path, renderer):
    g, s = box
    u = np.zeros((s.nodes.size, 3))
    u[:, 2] = 0.2 * s.points[:, 0]  # bending-like field, 6 mm at x = 30
    node = int(s.nodes[np.argmax(s.points[:, 0])])
    a = render_panels([Panel(surface=s, u=u, forces=[[0, 0, 0.4]], load_nodes=[node],
                             f_ref=0.4)], tmp_path / "a.png", panel_size=(320, 260))
    b = render_panels([Panel(surface=s, u=-u, forces=[[0, 0, -0.4]], load_nodes=[node],
                             f_ref=0.4)], tmp_path / "b.png", panel_size=(320, 260))
    img_a, fg_a = _liver_pixels(a)
    img_b, _ = _liver_pixels(b)
    assert img_a.shape == (260, 320, 3)
    assert 0.05 < fg_a.mean() < 0.95, fg_a.mean()  # something drawn, not everything
    assert np.abs(img_a - img_b).mean() > 1.0  # another field, another picture
    geo = render_panels([Panel(surface=s, label="geometry")] * 2, tmp_path / "g.png",
                        title="two boxes", panel_size=(200, 180))
    img_g, fg_g = _liver_pixels(geo)
    assert img_g.shape[1] == 400 and fg_g.mean() > 0.05


def test_gif_has_every_frame(tmp_path):
    from PIL import Image

    frames = [np.full((20, 30, 3), k * 60, np.uint8) for k in range(4)]
    path = write_gif(frames, tmp_path / "a.gif", fps=5)
    with Image.open(path) as im:
        assert im.n_frames == 4 and im.size == (30, 20)
    with pytest.raises(ValueError, match="no frames"):
        write_gif([], tmp_path / "b.gif")
