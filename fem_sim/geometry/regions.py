"""Named node regions that no file marks: the fixed vena-cava side of an imported liver."""

from __future__ import annotations

import numpy as np

from data_spec.geometry import Geometry


def default_vena_cava(g: Geometry, radius: float = 25.0) -> np.ndarray:
    """Surface nodes within ``radius`` mm of the most posterior (max y) surface point: the
    default fixed region of an imported liver (its vena-cava side in the usual orientation).
    """
    surf = g.surface_nodes
    top = surf[np.argmax(g.points[surf, 1])]
    return surf[np.linalg.norm(g.points[surf] - g.points[top], axis=1) <= radius]
