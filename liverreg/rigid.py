"""Turning a liver into the population's frame before the non-rigid registration.

Livers come in frames of their own: shifted, turned (a y-up modelling frame, a patient lying
otherwise) and sometimes mirrored (a left-handed frame). The non-rigid CPD of the template
(:mod:`liverreg.cpd`) starts from where the surfaces lie, so a liver turned by tens of degrees
is reached only by bending the template: its tetrahedra fold and the turn goes into the shape
coefficients as if it were shape.

:func:`orient` maps the liver into the population's frame: by the axis map of a frame the user
names (LPS, RAS or the population's own; :data:`FRAMES`) and the centroids, or, by default
(``auto``), by the orthogonal map x -> Q x + t that lays the liver's surface best onto the
population's mean surface. Candidates: the frame as given, and every signed permutation of the
liver's principal axes onto the mean surface's (48 maps, mirror images included); each is
refined by rigid ICP (proper rotations and translations, Kabsch's solution, nearest points
taken both ways) and scored by the symmetric mean distance between the surfaces' samples. The
best wins (a liver of the population stays where it is: the frame as given is a candidate).

A mirror image is a valid placement: the material is isotropic and the loads are forces, so
the mirrored problem's solution is the mirror of the solution (forces and displacements map
with Q like the points).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

# Maps from a frame to the population's (x: toward the right lobe, y: posterior, z: superior;
# fem_sim.geometry.phantom). DICOM/ITK's LPS has x toward the patient's left, NIfTI/Slicer's RAS
# y anterior: both are mirror images of the population's frame.
FRAMES = {"population": np.eye(3), "LPS": np.diag([-1.0, 1.0, 1.0]),
          "RAS": np.diag([1.0, -1.0, 1.0])}


@dataclass
class RigidFit:
    """x -> x @ Q.T + t, the liver's points into the population's frame."""

    Q: np.ndarray        # (3, 3) orthogonal; det -1: a mirror image
    t: np.ndarray        # (3,) mm
    distance: float      # symmetric mean distance of the samples after the fit, mm
    candidates: int      # starting maps tried (1: a declared frame)

    @property
    def mirrored(self) -> bool:
        return bool(np.linalg.det(self.Q) < 0)

    def nearest_frame(self) -> tuple[str, float]:
        """(frame, degrees): the frame of :data:`FRAMES` of the same handedness whose map Q
        differs least from, and the angle of the turn between them.
        """
        out = []
        for name, F in FRAMES.items():
            if np.linalg.det(F) * np.linalg.det(self.Q) > 0:
                c = (np.trace(self.Q @ F.T) - 1.0) / 2.0
                out.append((math.degrees(math.acos(np.clip(c, -1.0, 1.0))), name))
        deg, name = min(out)
        return name, deg

    def describe(self) -> str:
        name, deg = self.nearest_frame()
        return f"the {name} frame turned by {deg:.0f} degrees"


def kabsch(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, t): the proper rotation and translation minimising sum |R a + t - b|^2."""
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, cb - R @ ca


def principal_axes(X: np.ndarray) -> np.ndarray:
    """Columns: the principal directions of a point cloud, largest spread first."""
    w, V = np.linalg.eigh(np.cov((X - X.mean(axis=0)).T))
    return V[:, np.argsort(w)[::-1]]


def axis_maps() -> list[np.ndarray]:
    """The 48 signed permutation matrices (24 turns, 24 mirror images)."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            P = np.zeros((3, 3))
            P[np.arange(3), perm] = signs
            out.append(P)
    return out


def _distance(A, B) -> float:
    from scipy.spatial import cKDTree

    return float(0.5 * (cKDTree(B).query(A)[0].mean() + cKDTree(A).query(B)[0].mean()))


def _icp(X, Y, Q0, tree_y, iterations, tol):
    """Rigid ICP of X (mapped by Q0 first) onto Y; nearest points both ways."""
    from scipy.spatial import cKDTree

    X0 = X @ Q0.T
    R, t = np.eye(3), Y.mean(axis=0) - X0.mean(axis=0)
    last = np.inf
    for _ in range(iterations):
        Xm = X0 @ R.T + t
        dx, jx = tree_y.query(Xm)
        dy, jy = cKDTree(Xm).query(Y)
        dist = 0.5 * (dx.mean() + dy.mean())
        if last - dist < tol * dist:
            break
        last = dist
        R, t = kabsch(np.vstack([X0, X0[jy]]), np.vstack([Y[jx], Y]))
    return R @ Q0, t, _distance(X0 @ R.T + t, Y)


def orient(X: np.ndarray, Y: np.ndarray, frame: str = "auto", iterations: int = 60,
           tol: float = 1e-5, coarse: int = 200, finalists: int = 3,
           refine: bool = False) -> RigidFit:
    """The orthogonal map of liver samples X (n, 3) onto population samples Y (m, 3), mm.

    ``frame``: the liver's frame, a key of :data:`FRAMES` (its axis map, then the centroids
    matched: nothing is fitted; ``refine``: then refined by rigid ICP, proper rotations only,
    for livers known to lie in that frame up to the patient's pose); or ``"auto"``: the best
    rigid fit, ICP started from the frames and the 48 principal-axis maps (searched on
    ``coarse`` samples, the ``finalists`` best refined on all).
    """
    from scipy.spatial import cKDTree

    from liverreg.cpd import farthest_points

    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    if frame != "auto":
        if frame not in FRAMES:
            raise ValueError(f"frame: expected 'auto' or one of {', '.join(FRAMES)}, got "
                             f"{frame!r}")
        Q = FRAMES[frame]
        if not refine:
            t = Y.mean(axis=0) - (X @ Q.T).mean(axis=0)
            return RigidFit(Q=Q, t=t, distance=_distance(X @ Q.T + t, Y), candidates=1)
        Q, t, dist = _icp(X, Y, Q, cKDTree(Y), iterations, tol)
        return RigidFit(Q=Q, t=t, distance=dist, candidates=1)
    Ex, Ey = principal_axes(X), principal_axes(Y)
    starts = list(FRAMES.values()) + [Ey @ P @ Ex.T for P in axis_maps()]
    xs, ys = X[farthest_points(X, coarse)], Y[farthest_points(Y, coarse)]
    tree = cKDTree(ys)
    rough = sorted((_icp(xs, ys, Q0, tree, iterations, 1e-3)[2], i)
                   for i, Q0 in enumerate(starts))
    tree = cKDTree(Y)
    fits = [_icp(X, Y, starts[i], tree, iterations, tol) for _, i in rough[:finalists]]
    Q, t, dist = min(fits, key=lambda f: f[2])
    return RigidFit(Q=Q, t=t, distance=dist, candidates=len(starts))
