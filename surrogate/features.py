"""The paper's node-wise features, derived from the scene (what varies) as data.

For node n of a liver with fixed nodes F, at a load step with forces f_j (already scaled by the
load fraction) on load nodes p_j (j = 1..n_loads):

    [ x_n                                   node coordinates                         (3)
      x_c(n) - x_n, |x_c(n) - x_n|          to the closest fixed node c(n)            (4)
      x_F - x_n, |x_F - x_n|                to the fixed-node centroid x_F            (4)
      for each force j:  f_j, p_j - x_n, |p_j - x_n|                                  (7 each)
      material parameters (c_k, m_k, K)     only when the material varies
      shape coefficients                    only when the geometry varies ]

The per-node part that does not depend on the load (the first 11) is precomputed per geometry;
the rest is assembled inside jit from compact per-sample arrays, so a dataset of millions of
node samples never needs a materialised feature matrix. Pure functions of arrays (numpy or
jax.numpy through the ``xp`` argument).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

STATIC_DIM = 11
LOAD_BLOCK = 7


@dataclass(frozen=True)
class FeatureSpec:
    """Which feature blocks a scene's model has (the scene says; the trainer obeys)."""

    n_loads: int
    material_dim: int = 0   # 2 * n_terms + 1 when the material varies, else 0
    geometry_dim: int = 0   # number of shape coefficients when the geometry varies, else 0

    @property
    def dim(self) -> int:
        return STATIC_DIM + LOAD_BLOCK * self.n_loads + self.material_dim + self.geometry_dim

    def names(self) -> list[str]:
        n = ["x", "y", "z", "dfix_x", "dfix_y", "dfix_z", "dfix", "dcen_x", "dcen_y", "dcen_z",
             "dcen"]
        for j in range(self.n_loads):
            n += [f"f{j}_x", f"f{j}_y", f"f{j}_z", f"dl{j}_x", f"dl{j}_y", f"dl{j}_z", f"dl{j}"]
        n += [f"mat{i}" for i in range(self.material_dim)]
        n += [f"shape{i}" for i in range(self.geometry_dim)]
        return n

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_scene(cls, scene, n_shape: int = 0) -> FeatureSpec:
        varies = scene.varies
        n_terms = len(scene["material"]["c"])
        sample = scene["material"].get("sample")
        if sample and sample.get("kind") == "uniform":
            n_terms = len(sample["c"])
        elif sample and sample.get("kind") == "table":
            n_terms = len(sample["sets"][0]["c"])
        return cls(n_loads=scene["loads"]["count"],
                   material_dim=2 * n_terms + 1 if varies["material"] else 0,
                   geometry_dim=n_shape if varies["geometry"] else 0)


def static_node_features(points: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """(n_nodes, 11): coordinates, vector/distance to the closest fixed node and to the
    fixed-node centroid. numpy, once per geometry.
    """
    x = np.asarray(points, dtype=np.float64)
    fx = x[np.asarray(fixed)]
    out = np.empty((x.shape[0], STATIC_DIM))
    out[:, :3] = x
    for i in range(0, x.shape[0], 4096):
        d = fx[None, :, :] - x[i:i + 4096, None, :]
        k = np.argmin(np.einsum("ijk,ijk->ij", d, d), axis=1)
        v = d[np.arange(d.shape[0]), k]
        out[i:i + 4096, 3:6] = v
        out[i:i + 4096, 6] = np.linalg.norm(v, axis=1)
    c = fx.mean(axis=0) - x
    out[:, 7:10] = c
    out[:, 10] = np.linalg.norm(c, axis=1)
    return out


def node_features(static, forces, load_points, extra, xp=np):
    """Features of nodes: the one feature function of training and inference.

    Leading dimensions broadcast, so the same function builds the features of all nodes of
    one load case (the predictor: static (n, 11), forces (n_loads, 3)) and of a batch of
    examples from different cases (training: static (B, 11), forces (B, n_loads, 3)).

    Args:
        static: (..., 11) static node features (coordinates first).
        forces: (..., n_loads, 3) force vectors at this load step, N.
        load_points: (..., n_loads, 3) coordinates of the load nodes, mm.
        extra: (..., e) material parameters and/or shape coefficients (e may be 0).
        xp: numpy or jax.numpy.

    Returns:
        (..., dim) features, laid out as :meth:`FeatureSpec.names`.
    """
    lead = xp.broadcast_shapes(static.shape[:-1], forces.shape[:-2], extra.shape[:-1])

    def full(a):
        return xp.broadcast_to(a, lead + a.shape[-1:])

    d = load_points - static[..., None, :3]  # (..., n_loads, 3)
    dist = xp.sqrt(xp.sum(d * d, axis=-1, keepdims=True))
    blocks = [full(static)]
    for j in range(forces.shape[-2]):
        blocks += [full(forces[..., j, :]), full(d[..., j, :]), full(dist[..., j, :])]
    if extra.shape[-1]:
        blocks.append(full(extra))
    return xp.concatenate(blocks, axis=-1)


def material_vector(c, m, K) -> np.ndarray:
    return np.concatenate([np.atleast_1d(c), np.atleast_1d(m), [K]]).astype(np.float64)
