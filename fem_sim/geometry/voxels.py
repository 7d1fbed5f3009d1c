"""Meshes to voxel masks (ray parity): used for IoU/Dice of shape reconstructions and tests."""

from __future__ import annotations

import numpy as np

from data_spec.geometry import boundary_triangles


def voxelize(points: np.ndarray, cells: np.ndarray, spacing: float,
             origin=None, shape=None) -> tuple[np.ndarray, np.ndarray]:
    """Boolean mask of the voxels whose centre lies in a tetrahedral mesh (through its
    boundary, :func:`voxelize_surface`). Returns (mask, origin): voxel (i, j, k) has its centre
    at origin + spacing * (i, j, k). By default the grid covers the mesh's bounding box with a
    margin of 2 voxels.
    """
    return voxelize_surface(points, boundary_triangles(np.asarray(cells), points), spacing,
                            origin, shape)


def voxelize_surface(points: np.ndarray, tris: np.ndarray, spacing: float, origin=None,
                     shape=None, rule: str = "parity") -> tuple[np.ndarray, np.ndarray]:
    """Boolean mask of the voxel centres inside a closed triangle surface (rays along z).

    Each triangle toggles, in every (i, j) column its xy-projection covers, the voxels above
    the height where the column's ray crosses it; a running parity along z then marks the
    inside. ``rule = "nonzero"`` counts each crossing with its sign instead (entering +1,
    leaving -1, by the triangle's orientation) and marks where the count is not zero: the
    union of overlapping sheets, where parity would take their overlap out. Rays pass through
    voxel centres, shifted by a tiny irrational offset so that they never hit an edge or a
    vertex exactly. Returns (mask, origin) as :func:`voxelize`.
    """
    points = np.asarray(points, dtype=float)
    if origin is None:
        origin = points.min(axis=0) - 2 * spacing
    origin = np.asarray(origin, dtype=float)
    if shape is None:
        shape = tuple(np.ceil((points.max(axis=0) + 2 * spacing - origin) / spacing)
                      .astype(int) + 1)
    nx, ny, nz = shape
    toggles = np.zeros((nx, ny, nz + 1), dtype=np.int16)
    eps = np.array([1e-7 * np.sqrt(2.0), 1e-7 * np.sqrt(3.0)]) * spacing
    P = (points - origin) / spacing  # voxel units: centres at integers
    T = P[tris]  # (m, 3, 3)
    lo = np.clip(np.ceil(T[:, :, :2].min(axis=1) - eps / spacing).astype(int), 0, None)
    hi = np.minimum(np.floor(T[:, :, :2].max(axis=1)).astype(int), [nx - 1, ny - 1])
    ext = hi - lo + 1
    ok = np.all(ext > 0, axis=1)
    for key in np.unique(ext[ok], axis=0):
        sel = np.where(ok & np.all(ext == key, axis=1))[0]
        gi, gj = np.meshgrid(np.arange(key[0]), np.arange(key[1]), indexing="ij")
        offs = np.stack([gi.ravel(), gj.ravel()], axis=1)
        ij = lo[sel][:, None, :] + offs[None]  # (c, q, 2)
        q = ij + eps / spacing  # ray positions
        a, b, c = T[sel, 0][:, None], T[sel, 1][:, None], T[sel, 2][:, None]
        v0, v1 = (b - a)[..., :2], (c - a)[..., :2]
        w = q - a[..., :2]
        den = v0[..., 0] * v1[..., 1] - v0[..., 1] * v1[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (w[..., 0] * v1[..., 1] - w[..., 1] * v1[..., 0]) / den
            t = (v0[..., 0] * w[..., 1] - v0[..., 1] * w[..., 0]) / den
            hit = (den != 0) & (s >= 0) & (t >= 0) & (s + t <= 1)
            z = a[..., 2] + s * (b - a)[..., 2] + t * (c - a)[..., 2]
        k = np.clip(np.ceil(z[hit]).astype(int), 0, nz)
        i, j = ij[hit][:, 0], ij[hit][:, 1]
        # entering a closed outward surface upward crosses a triangle facing down (den < 0)
        sign = -np.sign(np.broadcast_to(den, hit.shape)[hit]).astype(np.int16)
        np.add.at(toggles, (i, j, k), 1 if rule == "parity" else sign)
    count = np.cumsum(toggles, axis=2, dtype=np.int32)[:, :, :nz]
    return ((count % 2) == 1 if rule == "parity" else count != 0), origin


def voxelize_majority(points: np.ndarray, tris: np.ndarray, spacing: float,
                      pad: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Inside mask of a surface that may be open or cross itself, as a segmentation's is:
    signed crossings along x, y and z (:func:`voxelize_surface` with the nonzero rule: the
    union of overlapping sheets), a voxel inside where two of the three agree. A hole spoils
    the count of the rays through it along one axis only, so the vote keeps it out. Returns
    (mask, origin) as :func:`voxelize`.
    """
    points = np.asarray(points, dtype=float)
    origin = points.min(axis=0) - pad * spacing
    shape = tuple(np.ceil((points.max(axis=0) + pad * spacing - origin) / spacing)
                  .astype(int) + 1)
    votes = np.zeros(shape, dtype=np.int8)
    for axis in range(3):
        order = [k for k in range(3) if k != axis] + [axis]  # the ray axis last
        mask, _ = voxelize_surface(points[:, order], tris, spacing, origin[order],
                                   tuple(shape[k] for k in order), rule="nonzero")
        votes += np.transpose(mask, np.argsort(order)).astype(np.int8)
    return votes >= 2, origin
