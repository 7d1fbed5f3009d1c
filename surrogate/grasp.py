"""What the surrogate adds to a grasp over a liver's Green's function
(:class:`data_spec.green_grasp.GreenGrasp`, the relation itself): how a force pressed on a
patch is spread over its nodes. numpy only.
"""

from __future__ import annotations

import numpy as np

# mm: beyond this pull a grasp's small-strain base is off by millimetres and its force far too
# low, the Ogden liver stiffening (docs/surgical_loads.md): predict-liver and the manipulator
# say so
SMALL_PULL_MM = 5.0


def patch_weights(points: np.ndarray, triangles: np.ndarray, patch, centre: int,
                  radius: float) -> np.ndarray:
    """(len(patch),) the shares of a force pressed on a patch (summing to 1) that its nodes
    carry as nodal forces: each node's lumped surface area (a third of its triangles') times
    the bump (1 - (r / radius)^2)^2 of its distance r to ``centre``, the footprint the
    solver's PatchLoad spreads as a traction (the node at the centre alone when the patch is
    that one node).
    """
    patch = np.asarray(patch, dtype=np.int64)
    t = np.asarray(triangles, dtype=np.int64)
    x = points[t]
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
    lumped = np.zeros(points.shape[0])
    for k in range(3):
        np.add.at(lumped, t[:, k], area / 3.0)
    r = np.linalg.norm(points[patch] - points[int(centre)], axis=1) / radius
    w = lumped[patch] * np.clip(1.0 - r**2, 0.0, None) ** 2
    if w.sum() <= 0.0:
        raise ValueError(f"the patch around node {centre} carries no area")
    return w / w.sum()
