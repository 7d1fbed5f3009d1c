"""Which nodes a scene's random loads may act on: the rule both sides read from the scene's
``[loads]`` table (the solver draws load nodes from it; the trainer's exported model warns when
asked to predict a load elsewhere, where it never saw one).
"""

from __future__ import annotations

import numpy as np

NEAR_RADIUS = 20.0   # mm: a site's reach (loads.near) when loads.near_radius is not given


def eligible_load_nodes(loads: dict, points: np.ndarray, surface_nodes: np.ndarray,
                        fixed: np.ndarray) -> np.ndarray:
    """Node ids a random load may act on: surface (or all) nodes, not fixed, at least
    ``loads["min_distance_to_fixed"]`` mm from every fixed node, and with ``loads["near"]``
    within ``loads["near_radius"]`` (default :data:`NEAR_RADIUS`) mm of that site.
    """
    cand = surface_nodes if loads["eligible"] == "surface" else np.arange(points.shape[0])
    cand = np.setdiff1d(cand, fixed)
    if loads.get("near") is not None:
        reach = loads.get("near_radius") or NEAR_RADIUS
        cand = cand[np.linalg.norm(points[cand] - np.asarray(loads["near"], float),
                                   axis=1) <= reach]
    dmin = loads["min_distance_to_fixed"]
    if dmin > 0 and cand.size and np.size(fixed):
        cand = cand[min_distance(points[cand], points[fixed]) >= dmin]
    return cand


def min_distance(a: np.ndarray, b: np.ndarray, chunk: int = 2048) -> np.ndarray:
    """For each point of ``a``, its distance to the nearest point of ``b``."""
    out = np.empty(a.shape[0])
    for i in range(0, a.shape[0], chunk):
        d = a[i:i + chunk, None, :] - b[None, :, :]
        out[i:i + chunk] = np.sqrt(np.min(np.einsum("ijk,ijk->ij", d, d), axis=1))
    return out


def grasp_patch(points: np.ndarray, surface_nodes: np.ndarray, centre: int,
                radius: float) -> np.ndarray:
    """A grasping tool's patch, the rule the solver moves and the surrogate answers alike:
    the surface nodes within ``radius`` mm of the node ``centre`` (which is one of them).
    """
    surf = np.asarray(surface_nodes, dtype=np.int64)
    return surf[np.linalg.norm(points[surf] - points[int(centre)], axis=1) <= radius]
