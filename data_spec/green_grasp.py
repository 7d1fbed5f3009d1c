"""A grasp over a liver's small-strain Green's function: tools that each hold a patch of the
surface (:func:`data_spec.eligible_loads.grasp_patch`, the rule the solver moves) and move it
rigidly, and the force each tool feels.

In small strain a held patch is the set of nodal forces f that puts every patch node at its
tool's displacement: G_PP f = B d, with G_PP the Green's function among the patch nodes
(symmetric positive definite by Maxwell-Betti: the body is held by its fixed region) and B
stacking each tool's displacement d on its nodes. The field is u = G f (every output node's
response to those forces) and each tool's force is the sum of its nodes' f. Both are linear
in d, so one factorisation per grasp position gives the field per millimetre of pull H and the
tools' stiffness K = B^T G_PP^-1 B: a frame is then u = H d, a haptic loop's force K d.

The one relation between a small-strain file's unit responses (:mod:`data_spec.linear_fields`)
and a grasp: ``fem_sim linear`` writes a grasp dataset's responses with it, the surrogate
answers a grasp at run time with it. numpy only.
"""

from __future__ import annotations

import numpy as np


class GreenGrasp:
    """Tools holding the node sets ``patches`` (mesh ids) of a liver whose Green's function
    ``green`` (n_g, 3, n_out, 3) mm/N has its rows at the mesh nodes ``green_nodes`` (the
    surface off the fixed region) and its columns at ``output_nodes``. ValueError naming the
    node when a patch holds a node without a unit response (fixed, interior) or unseen.

        grasp = GreenGrasp(green, green_nodes, output_nodes, [patch])
        u, force = grasp([[0.0, 0.0, 20.0]])    # (n_out, 3) mm, (1, 3) N for a 20 mm pull
    """

    def __init__(self, green: np.ndarray, green_nodes, output_nodes, patches):
        green_nodes, output_nodes = np.asarray(green_nodes), np.asarray(output_nodes)
        self.patches = [np.asarray(p, dtype=np.int64) for p in patches]
        nodes = np.concatenate(self.patches) if self.patches else np.zeros(0, np.int64)
        if nodes.size == 0 or any(p.size == 0 for p in self.patches):
            raise ValueError("a grasp needs at least one tool, each holding at least one node")
        rows, cols = _positions(green_nodes, nodes, "has no unit response (a fixed or "
                                "interior node: a tool holds the free surface)"), \
            _positions(output_nodes, nodes, "is not an output node of the Green's function")
        m, t = nodes.size, len(self.patches)
        gpp = np.asarray(green[rows][:, :, cols], dtype=np.float64).reshape(3 * m, 3 * m)
        gpp = 0.5 * (gpp + gpp.T)   # symmetric in exact arithmetic (stored in float32)
        # each node's tool (its row of the identity), each coordinate its own: (3m, 3T)
        b = np.kron(np.repeat(np.eye(t), [p.size for p in self.patches], axis=0), np.eye(3))
        try:
            c = np.linalg.cholesky(gpp)   # nodal forces per mm of each tool's pull:
            x = np.linalg.solve(c.T, np.linalg.solve(c, b))
        except np.linalg.LinAlgError:
            raise ValueError("the patches' Green's function is not positive definite: a "
                             "patch node twice, or two tools on the same nodes") from None
        self.nodal_forces = x.reshape(m, 3, 3 * t)                 # N/mm
        self.stiffness = b.T @ x                                   # (3T, 3T) N/mm
        self.field = np.einsum("manb,mat->nbt", green[rows], self.nodal_forces,
                               dtype=np.float64)                   # (n_out, 3, 3T) mm/mm

    def force(self, d) -> np.ndarray:
        """(T, 3) N: each tool's force on the liver for the displacements ``d`` (T, 3) mm."""
        return (self.stiffness @ self._flat(d)).reshape(-1, 3)

    def __call__(self, d) -> tuple[np.ndarray, np.ndarray]:
        """(u (n_out, 3) mm, force (T, 3) N) for the tools' displacements ``d`` (T, 3) mm."""
        flat = self._flat(d)
        return self.field @ flat, (self.stiffness @ flat).reshape(-1, 3)

    def _flat(self, d) -> np.ndarray:
        d = np.asarray(d, dtype=np.float64)
        if d.shape != (len(self.patches), 3) or not np.all(np.isfinite(d)):
            raise ValueError(f"tool displacements: expected finite ({len(self.patches)}, 3) mm, "
                             f"got shape {d.shape}")
        return d.reshape(-1)


def _positions(ids: np.ndarray, nodes: np.ndarray, why: str) -> np.ndarray:
    """Each of ``nodes``' position in the sorted-or-not id list ``ids``; ValueError naming
    the first node not in it.
    """
    order = np.argsort(ids)
    at = np.searchsorted(ids, nodes, sorter=order)
    at = np.minimum(at, ids.size - 1)
    pos = order[at]
    missing = ids[pos] != nodes
    if missing.any():
        raise ValueError(f"grasped node {int(nodes[missing][0])} {why}")
    return pos
