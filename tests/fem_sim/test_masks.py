"""Segmentation masks -> tetrahedral livers (the paper's route) and meshes -> masks."""


import numpy as np
import pytest

from fem_sim.geometry.masks import clean_mask, mesh_mask_file, read_mask, voxelize
from fem_sim.geometry.phantom import make_phantom, mesh_volume
from fem_sim.geometry.source import GeometryError
from tests.fem_sim.test_geometry import check_geometry

pytest.importorskip("skimage")


def test_voxelize_measures_a_box_exactly():
    """A 10 x 20 x 30 mm box (6 tetrahedra), 1 mm voxels offset by half a voxel: exactly
    10 * 20 * 30 voxel centres lie inside."""
    from tests.fixtures import box_mesh

    g = box_mesh(1)
    pts = g.points * np.array([10.0, 20.0, 30.0])
    mask, origin = voxelize(pts, g.cells, 1.0, origin=np.array([0.5, 0.5, 0.5]),
                            shape=(12, 22, 32))
    assert mask.sum() == 10 * 20 * 30
    assert mask[:10, :20, :30].all()


def test_cleaning_removes_specks_and_fills_cavities():
    m = np.zeros((40, 40, 40), bool)
    m[5:35, 5:35, 5:35] = True
    m[15:20, 15:20, 15:20] = False  # internal cavity
    m[1, 1, 1] = True  # speck
    out, sp = clean_mask(m, [1.0, 1.0, 1.0])
    assert not out[1, 1, 1] and out[17, 17, 17]
    assert np.allclose(sp, 1.0)
    # the opening rounds the cube's 12 edges and 8 corners (radius 3 voxels): a few % only
    assert 0.92 * 30**3 <= int(out.sum()) <= 30**3


@pytest.mark.slow
def test_phantom_mask_round_trip_keeps_the_volume(tmp_path):
    """Phantom -> voxels (anisotropic, like CT) -> .npz file -> mesh: volume within 3 %,
    closed, outward, fixed region on the surface."""
    spacing = [0.8, 0.8, 2.0]
    g = make_phantom(0, 10.0)
    vol = mesh_volume(g)
    sp = np.array(spacing)
    # anisotropic voxelisation: scale the mesh so that one voxel = one unit, then back
    mask, origin = voxelize(g.points / sp, g.cells, 1.0)
    np.savez(tmp_path / "phantom_mask.npz", mask=mask, spacing=sp, origin=origin * sp)
    out = mesh_mask_file(tmp_path / "phantom_mask.npz", 10.0)
    v2 = check_geometry(out)
    assert v2 == pytest.approx(vol, rel=0.03)
    # in place: the mesh lies where the phantom is
    np.testing.assert_allclose(out.points.mean(axis=0), g.points.mean(axis=0), atol=3.0)


def test_nifti_mask_reads_spacing_and_origin(tmp_path):
    nib = pytest.importorskip("nibabel")
    m = np.zeros((20, 30, 10), np.uint8)
    m[5:15, 5:25, 2:8] = 1
    aff = np.diag([0.7, 0.7, 2.5, 1.0])
    aff[:3, 3] = [10.0, -5.0, 3.0]
    nib.save(nib.Nifti1Image(m, aff), str(tmp_path / "m.nii.gz"))
    mask, sp, origin = read_mask(tmp_path / "m.nii.gz")
    np.testing.assert_allclose(sp, [0.7, 0.7, 2.5])
    np.testing.assert_allclose(origin, [10.0, -5.0, 3.0])
    assert mask.sum() == 10 * 20 * 6


def test_bad_masks_get_clear_errors(tmp_path):
    np.save(tmp_path / "empty.npy", np.zeros((5, 5, 5)))
    np.save(tmp_path / "flat.npy", np.ones((5, 5)))
    with pytest.raises(GeometryError, match="needs its voxel spacing"):
        read_mask(tmp_path / "empty.npy")
    with pytest.raises(GeometryError, match="empty.npy: the mask is empty"):
        read_mask(tmp_path / "empty.npy", spacing=1.0)
    with pytest.raises(GeometryError, match="flat.npy: expected a 3-D mask"):
        read_mask(tmp_path / "flat.npy", spacing=1.0)
    np.save(tmp_path / "cube.npy", np.ones((4, 4, 4)))
    with pytest.raises(GeometryError, match="spacing must be 3 positive"):
        read_mask(tmp_path / "cube.npy", spacing=[1.0, -1.0, 1.0])
    with pytest.raises(GeometryError, match="not found"):
        read_mask(tmp_path / "missing.npy", spacing=1.0)
    thin = np.zeros((30, 30, 30), bool)
    thin[10:20, 10:20, 15] = True  # one voxel thick: opening removes it
    with pytest.raises(GeometryError, match="vanishes after opening"):
        clean_mask(thin, [1.0, 1.0, 1.0])
