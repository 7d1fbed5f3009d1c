"""Boundary conditions and loads of one simulation, as plain data (no dolfinx): what the user
gives :meth:`fem_sim.OgdenProblem.solve`. :mod:`fem_sim.solver.discretisation` maps them to dofs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Constraint:
    """Prescribed displacement of source nodes: ``values`` (mm, at load fraction 1) for the
    given components. The default is a fixed (zero-displacement) node set.
    """

    nodes: np.ndarray
    components: tuple[int, ...] = (0, 1, 2)
    values: float | np.ndarray = 0.0


@dataclass
class NodalLoad:
    """Forces (N, at load fraction 1) on source nodes; repeated nodes add up."""

    nodes: np.ndarray
    forces: np.ndarray

    def __post_init__(self):
        self.nodes = np.atleast_1d(np.asarray(self.nodes, dtype=np.int64))
        self.forces = np.asarray(self.forces, dtype=np.float64).reshape(-1, 3)
        if self.nodes.shape[0] != self.forces.shape[0]:
            raise ValueError(f"NodalLoad: {self.nodes.shape[0]} nodes but "
                             f"{self.forces.shape[0]} force vectors")
        if not np.all(np.isfinite(self.forces)):
            raise ValueError("NodalLoad: forces contain NaN or inf")


@dataclass
class PatchLoad:
    """A total force (N, at load fraction 1) spread as a traction over the boundary around a
    centre point: t(x) = force w(x) / integral(w ds), with the footprint
    w = (1 - (d / radius)^2)^2 for d = |x - centre| < radius ("bump", smooth, an indenter's
    pressure profile) or w = 1 inside ("uniform"). The applied total force is exactly ``force``
    and the load is a proper surface integral, so it converges under refinement (P1 and P2),
    unlike a point force.
    """

    centre: np.ndarray
    force: np.ndarray
    radius: float
    profile: str = "bump"

    def __post_init__(self):
        self.centre = np.asarray(self.centre, dtype=np.float64).reshape(3)
        self.force = np.asarray(self.force, dtype=np.float64).reshape(3)
        if not (np.all(np.isfinite(self.force)) and np.all(np.isfinite(self.centre))):
            raise ValueError("PatchLoad: NaN or inf in centre or force")
        if not self.radius > 0 or self.profile not in ("bump", "uniform"):
            raise ValueError("PatchLoad: radius must be > 0 and profile 'bump' or 'uniform'")

    def weight(self, x: np.ndarray) -> np.ndarray:
        d2 = np.sum((x - self.centre) ** 2, axis=1) / self.radius**2
        if self.profile == "uniform":
            return (d2 <= 1.0).astype(np.float64)
        return np.clip(1.0 - d2, 0.0, None) ** 2
