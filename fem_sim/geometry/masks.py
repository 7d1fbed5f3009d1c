"""Segmentation masks in, tetrahedral livers out (the reference paper's route), and meshes back
to masks (voxelisation, used for tests and for IoU/Dice of shape reconstructions).

    mask (.npy + spacing, .npz with ``mask`` and ``spacing``, NIfTI .nii/.nii.gz)
      -> resample to 1 mm (trilinear on the 0/1 image, threshold 0.5)
      -> opening, then closing, with a ball of radius 3 voxels
      -> largest connected component, internal cavities filled
      -> surface by marching cubes on the (lightly Gaussian-smoothed) image
      -> Taubin smoothing (no shrinkage)
      -> tetrahedra by gmsh at the requested size (fem_sim.geometry.surfaces)

Runs on one process; the batch generator calls it on rank 0 before any MPI work.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from data_spec.geometry import Geometry
from fem_sim.geometry.errors import GeometryError
from fem_sim.geometry.regions import default_vena_cava
from fem_sim.geometry.surfaces import clean_surface, mesh_closed_surface
from fem_sim.geometry.voxels import voxelize, voxelize_surface  # noqa: F401  (re-exported)


def _npy(path: Path, spacing):
    if spacing is None:
        raise GeometryError(f"{path}: a .npy mask needs its voxel spacing (mm), e.g. "
                            "geometry.spacing = [0.8, 0.8, 1.5]")
    return np.load(path, allow_pickle=False), spacing, np.zeros(3)


def _npz(path: Path, spacing):
    with np.load(path, allow_pickle=False) as z:
        if "mask" not in z:
            raise GeometryError(f"{path}: no 'mask' array (found {sorted(z.files)})")
        if spacing is None and "spacing" not in z:
            raise GeometryError(f"{path}: no 'spacing' array and none given")
        origin = np.asarray(z["origin"], dtype=float) if "origin" in z else np.zeros(3)
        return z["mask"], z["spacing"] if spacing is None else spacing, origin


def _nifti(path: Path, spacing):
    import nibabel

    img = nibabel.load(str(path))
    lin = img.affine[:3, :3]
    if np.abs(lin - np.diag(np.diag(lin))).max() > 1e-6 * np.abs(lin).max():
        raise GeometryError(f"{path}: rotated/oblique NIfTI affines are not supported")
    return (np.asarray(img.dataobj), np.abs(np.diag(lin)) if spacing is None else spacing,
            img.affine[:3, 3].copy())


def read_mask(path: str | Path, spacing=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mask bool (nx, ny, nz), spacing (3,) mm, origin (3,) mm) from a file.

    ``.npy`` needs ``spacing`` (mm per voxel, scalar or 3 values); ``.npz`` holds ``mask`` and
    ``spacing`` (and optionally ``origin``); NIfTI takes spacing and origin from its affine
    (axis-aligned affines only).
    """
    path = Path(path)
    if not path.exists():
        raise GeometryError(f"{path}: mask file not found")
    name = path.name.lower()
    readers = {".npy": _npy, ".npz": _npz, ".nii": _nifti, ".nii.gz": _nifti}
    reader = next((r for ext, r in readers.items() if name.endswith(ext)), None)
    if reader is None:
        raise GeometryError(f"{path}: unknown mask format (expected .npy, .npz, .nii, .nii.gz)")
    try:
        mask, spacing, origin = reader(path, spacing)
    except GeometryError:
        raise
    except Exception as exc:
        raise GeometryError(f"{path}: cannot read mask: {exc}") from None
    mask = np.asarray(mask)
    if mask.ndim != 3:
        raise GeometryError(f"{path}: expected a 3-D mask, got shape {mask.shape}")
    spacing = np.broadcast_to(np.asarray(spacing, dtype=float), (3,)).copy()
    if not np.all(np.isfinite(spacing) & (spacing > 0)):
        raise GeometryError(f"{path}: spacing must be 3 positive numbers, got {spacing}")
    if not mask.any():
        raise GeometryError(f"{path}: the mask is empty")
    return mask > 0, spacing, origin


def _ball(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    return (r[:, None, None] ** 2 + r[None, :, None] ** 2 + r[None, None, :] ** 2) <= radius**2


def clean_mask(mask: np.ndarray, spacing, voxel: float = 1.0, radius: int = 3):
    """Resampled (``voxel`` mm), opened then closed (ball of ``radius`` voxels), largest
    component, cavities filled. Returns (mask, voxel spacing (3,)); the first voxel centre stays
    where it was.
    """
    from scipy import ndimage

    spacing = np.asarray(spacing, dtype=float)
    zoom = spacing / voxel
    if np.allclose(zoom, 1.0):
        m = mask.astype(bool)
    else:
        m = ndimage.zoom(mask.astype(np.float32), zoom, order=1, grid_mode=False) > 0.5
    pad = radius + 2
    m = np.pad(m, pad)
    ball = _ball(radius)
    m = ndimage.binary_opening(m, ball)
    m = ndimage.binary_closing(m, ball)
    lab, n = ndimage.label(m)
    if n == 0:
        raise GeometryError("the mask vanishes after opening with a radius-"
                            f"{radius} ball (is it thinner than {2 * radius} voxels?)")
    if n > 1:
        m = lab == np.argmax(np.bincount(lab.ravel())[1:]) + 1
    m = ndimage.binary_fill_holes(m)
    m = m[pad:-pad, pad:-pad, pad:-pad]
    # After zoom(grid_mode=False) the first and last voxel centres keep their positions.
    new_spacing = np.where(np.array(mask.shape) > 1,
                           spacing * (np.array(mask.shape) - 1)
                           / np.maximum(np.array(m.shape) - 1, 1), voxel)
    return m, new_spacing


def taubin_smooth(points, tris, iterations: int = 20, lam: float = 0.5, mu: float = -0.53):
    """Taubin's lambda/mu smoothing (umbrella operator): removes voxel steps without the
    shrinkage of plain Laplacian smoothing.
    """
    from scipy.sparse import coo_matrix, diags

    n = points.shape[0]
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    A = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    A.data[:] = 1.0
    W = diags(1.0 / np.asarray(A.sum(axis=1)).ravel()) @ A
    p = points.copy()
    for _ in range(iterations):
        p = p + lam * (W @ p - p)
        p = p + mu * (W @ p - p)
    return p


def mask_surface(mask, spacing, origin=(0.0, 0.0, 0.0), *, voxel: float = 1.0,
                 radius: int = 3, sigma: float = 0.6, smooth_iterations: int = 20):
    """Closed, outward-oriented triangle surface (points in mm, triangles) of a mask."""
    from scipy import ndimage
    from skimage.measure import marching_cubes

    m, sp = clean_mask(mask, spacing, voxel, radius)
    f = np.pad(m.astype(np.float32), 2)
    if sigma > 0:
        f = ndimage.gaussian_filter(f, sigma)
    verts, faces, _, _ = marching_cubes(f, 0.5, spacing=tuple(sp))
    verts = verts - 2 * sp + np.asarray(origin, dtype=float)
    verts = taubin_smooth(verts, faces, smooth_iterations)
    return clean_surface(verts, faces.astype(np.int64), "mask surface")


def mesh_mask(mask, spacing, mesh_size: float, origin=(0.0, 0.0, 0.0), *,
              description: str = "mask", fixed_radius: float = 25.0, **kw) -> Geometry:
    """Tetrahedral mesh of a segmentation mask (see the module docstring). As a default fixed
    region (``vena_cava``) it marks the surface nodes within ``fixed_radius`` mm of the most
    posterior (max y) surface point, as :func:`fem_sim.geometry.repair.mesh_surface_file`.
    """
    pts, tris = mask_surface(mask, spacing, origin, **kw)
    g = mesh_closed_surface(pts, tris, mesh_size, f"{description}, mesh size {mesh_size}")
    g.regions["vena_cava"] = default_vena_cava(g, fixed_radius)
    return g


def mesh_mask_file(path, mesh_size: float, spacing=None, **kw) -> Geometry:
    mask, sp, origin = read_mask(path, spacing)
    return mesh_mask(mask, sp, mesh_size, origin, description=Path(path).name, **kw)
