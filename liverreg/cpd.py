"""Non-rigid Coherent Point Drift (CPD) and the PCA of a registered population: the shape
parametrisation of scene 4 (the reference paper's section 2.4.2), in numpy and scipy only, so
that the solver (which builds the population) and the trainer (which places a new liver in
it) share one implementation.

* CPD (Myronenko & Song 2010), non-rigid, with Gaussian motion coherence: the template points Y
  move by v(y) = sum_m G(y, y_m) W_m, G = exp(-|y - y'|^2 / (2 beta^2)); EM on the Gaussian
  mixture centred at the moved template points, with an outlier weight w. Both point sets are
  normalised (zero mean, unit RMS radius) as in the original implementation, so beta and
  lambda are in units of the liver's size.
* Staged (beta, lambda) schedule of the paper's Table 2: (8, 6), (2, 1.5), (1.2, 0.9),
  (0.6, 0.45), (0.3, 0.225); a stage ends when the relative change of sigma^2 drops below
  5e-3, 1e-3, 1e-4, 1e-5 (the last stage also ends at 1e-5). Each stage starts from the
  previous one's moved template, so the smooth stages fix the global shape before the local
  ones refine it.
* CPD runs on coarse point sets (farthest-point samples of the surfaces, ``n_points`` each);
  the fitted displacement field is then evaluated at every template node.
* PCA: each liver r gives D_r = M_r - M (template surface nodes, flattened); the population's
  mean displacement and principal components come from an SVD; a liver's coefficients are the
  projections of D_r - mean (:func:`project`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from data_spec.geometry import Geometry
from liverreg.morph import SurfaceMorph

STAGED = ((8.0, 6.0, 5e-3), (2.0, 1.5, 1e-3), (1.2, 0.9, 1e-4), (0.6, 0.45, 1e-5),
          (0.3, 0.225, 1e-5))
PLAIN = ((2.0, 3.0, 1e-5),)  # the original implementation's defaults, one stage


def farthest_points(points: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """Indices of ``n`` well-spread points (greedy farthest-point sampling)."""
    n = min(n, points.shape[0])
    idx = np.empty(n, dtype=np.int64)
    idx[0] = np.random.default_rng(seed).integers(points.shape[0])
    d = np.linalg.norm(points - points[idx[0]], axis=1)
    for k in range(1, n):
        idx[k] = int(np.argmax(d))
        d = np.minimum(d, np.linalg.norm(points - points[idx[k]], axis=1))
    return idx


def _sqdist(A, B):
    return np.maximum((A * A).sum(1)[:, None] + (B * B).sum(1)[None] - 2.0 * A @ B.T, 0.0)


@dataclass
class CPDResult:
    """A fitted non-rigid CPD: the displacement field, stage by stage, in normalised frames."""

    x_mean: np.ndarray       # normalisation of the target (x) and template (y) point sets
    x_scale: float
    y_mean: np.ndarray
    y_scale: float
    stages: list = field(default_factory=list)  # (beta, W, Y_start) per stage, normalised
    iterations: list = field(default_factory=list)
    sigma2: float = 0.0      # final GMM variance (normalised units)

    def transform(self, Z: np.ndarray) -> np.ndarray:
        """Moved positions (target frame, mm) of template points Z (template frame, mm)."""
        z = (Z - self.y_mean) / self.y_scale
        for beta, W, Ys in self.stages:
            z = z + np.exp(-_sqdist(z, Ys) / (2.0 * beta * beta)) @ W
        return z * self.x_scale + self.x_mean


def cpd_nonrigid(X: np.ndarray, Y: np.ndarray, schedule=STAGED, w: float = 0.0,
                 max_iterations: int = 150) -> CPDResult:
    """Non-rigid CPD of template points Y (m, 3) onto target points X (n, 3), both in mm."""
    xm, ym = X.mean(0), Y.mean(0)
    xs = math.sqrt(((X - xm) ** 2).sum(1).mean())
    ys = math.sqrt(((Y - ym) ** 2).sum(1).mean())
    x, y0 = (X - xm) / xs, (Y - ym) / ys
    n, d = x.shape
    m = y0.shape[0]
    res = CPDResult(x_mean=xm, x_scale=xs, y_mean=ym, y_scale=ys)
    sigma2 = _sqdist(x, y0).sum() / (d * n * m)
    xx = (x * x).sum(1)
    Ys = y0
    for beta, lam, tol in schedule:
        G = np.exp(-_sqdist(Ys, Ys) / (2.0 * beta * beta))
        W = np.zeros((m, d))
        T = Ys
        its = 0
        for _ in range(max_iterations):
            its += 1
            # E-step: posterior of template point m for target point n
            P = _sqdist(T, x)
            P *= -0.5 / sigma2
            np.exp(P, out=P)
            c = (2.0 * math.pi * sigma2) ** (d / 2) * w / (1.0 - w) * m / n if w > 0 else 0.0
            den = P.sum(0) + c
            den[den == 0] = np.finfo(float).tiny
            P /= den
            P1, Pt1 = P.sum(1), P.sum(0)
            Np = P1.sum()
            PX = P @ x
            W = _m_step(G, P1, PX, Ys, lam * sigma2)
            T = Ys + G @ W
            s_old = sigma2
            sigma2 = ((Pt1 * xx).sum() - 2.0 * (PX * T).sum() + (P1 * (T * T).sum(1)).sum()) \
                / (Np * d)
            sigma2 = max(sigma2, 1e-10)
            if abs(s_old - sigma2) / s_old < tol:
                break
        res.stages.append((beta, W, Ys))
        res.iterations.append(its)
        Ys = T
    res.sigma2 = sigma2
    return res


def _m_step(G: np.ndarray, P1: np.ndarray, PX: np.ndarray, Ys: np.ndarray, c: float):
    """W of CPD's M-step, (diag(P1) G + c I) W = PX - diag(P1) Ys, solved in its symmetric
    form: with D = diag(P1) and W = D^(1/2) Z, (D^(1/2) G D^(1/2) + c I) Z = D^(-1/2) PX -
    D^(1/2) Ys (the first equation's rows multiplied by D^(-1/2)), whose matrix is symmetric
    positive definite (G is a Gaussian kernel, c > 0): a Cholesky factorisation, half an LU's
    work, the same W to round-off. A template point no target claims (P1 = 0) has PX = 0 and
    W = 0 in both forms.
    """
    from scipy.linalg import cho_factor, cho_solve

    s = np.sqrt(P1)[:, None]
    A = s * G * s.T
    A[np.diag_indices_from(A)] += c
    rhs = np.divide(PX, s, out=np.zeros_like(PX), where=s > 0) - s * Ys
    return s * cho_solve(cho_factor(A, lower=True, overwrite_a=True, check_finite=False), rhs,
                         check_finite=False)


def chamfer(A: np.ndarray, B: np.ndarray) -> float:
    """Symmetric mean nearest-neighbour distance between two point sets (mm)."""
    from scipy.spatial import cKDTree

    return 0.5 * (cKDTree(B).query(A)[0].mean() + cKDTree(A).query(B)[0].mean())


def surface_samples(g: Geometry, n_points: int) -> np.ndarray:
    surf = g.surface_nodes
    return g.points[surf[farthest_points(g.points[surf], n_points)]]


@dataclass
class Population:
    """Registered population: template surface displacements, their PCA and coefficients."""

    template: Geometry
    displacements: np.ndarray        # (R, n_surface_nodes * 3): template surface nodes
    mean: np.ndarray                 # (n_surface_nodes * 3,)
    components: np.ndarray           # (K, n_surface_nodes * 3), orthonormal rows
    singular_values: np.ndarray      # (K,)
    coefficients: np.ndarray         # (R, K)
    registration_error: np.ndarray   # (R,) mean surface distance, moved template <-> liver (mm)
    iterations: list
    inverted: np.ndarray = None      # (R,) template tetrahedra the placement turned inside out
    min_jacobian: np.ndarray = None  # (R,) smallest moved / template cell volume per liver
    template_member: bool = True     # the template is one of the livers (else: given apart)

    @property
    def explained_variance_ratio(self) -> np.ndarray:
        v = self.singular_values**2
        return v / v.sum()

    def reconstruct(self, r: int, n: int) -> np.ndarray:
        """Template surface nodes (``template.surface_nodes`` order) of liver r rebuilt from
        its first n coefficients.
        """
        d = self.mean + self.coefficients[r, :n] @ self.components[:n]
        return self.template.points[self.template.surface_nodes] + d.reshape(-1, 3)

    def surface_triangles(self) -> np.ndarray:
        """The template's boundary triangles, indexing :meth:`reconstruct`'s rows."""
        M = self.template
        renum = np.full(M.n_nodes, -1)
        renum[M.surface_nodes] = np.arange(M.surface_nodes.size)
        return renum[M.surface_triangles]


@dataclass
class Registration:
    """The template registered onto one liver."""

    points: np.ndarray   # (n_template, 3) every template node moved onto the liver, mm
    residual: float      # symmetric mean distance, moved template surface <-> liver, mm
    inverted: int        # template tetrahedra the move turned inside out
    iterations: list     # CPD iterations per stage
    min_jacobian: float = 1.0  # smallest moved / template cell volume
    unfold_rounds: int = 0     # rounds of relaxation the surface needed to fold no cell


def register(morph: SurfaceMorph, Y: np.ndarray, triangles: np.ndarray, X: np.ndarray,
             liver_dense: np.ndarray, schedule=STAGED) -> Registration:
    """One liver's registration, as the population and a new liver both get it: CPD of the
    template's surface samples Y onto the liver's X, the template surface moved by it and
    the interior with it, with no cell folded where that can be had
    (:meth:`liverreg.morph.SurfaceMorph.unfold`; ``morph``: the template with its surface
    nodes as boundary), and the residual between the densely sampled surfaces (the moved
    template's boundary ``triangles`` and ``liver_dense``). Where the relaxation cannot undo a
    fold, the finest CPD stages are dropped one by one (a smoother field) until none is left.
    """
    res = cpd_nonrigid(X, Y, schedule)
    stages = list(res.stages)
    for k in range(len(stages), 0, -1):  # the finest stages fold first: drop them if need be
        res.stages = stages[:k]
        moved, rounds = morph.unfold(res.transform(morph.points[morph.boundary]))
        if morph.inverted(moved) == 0:
            break
    return Registration(points=moved,
                        residual=float(chamfer(dense_surface(moved, triangles), liver_dense)),
                        inverted=morph.inverted(moved), iterations=res.iterations,
                        min_jacobian=morph.min_jacobian(moved), unfold_rounds=rounds)


def surface_displacements(z) -> np.ndarray:
    """(R, 3 s) each liver's template-surface displacement from an open population.npz: the
    mean and every component (exact, not a truncation to fewer components).
    """
    return z["mean"] + z["coefficients"] @ z["components"]


def project(displacements: np.ndarray, mean: np.ndarray, components: np.ndarray) -> np.ndarray:
    """Shape coefficients of flattened template-surface displacements (..., 3 n_surface):
    their projections, less the population mean, on the orthonormal rows of ``components``.
    """
    return (np.asarray(displacements) - mean) @ np.asarray(components).T


def build_population(livers: list[Geometry], template: int | Geometry = 0,
                     n_points: int = 600, schedule=STAGED, progress=None,
                     known: dict | None = None) -> Population:
    """Register the template (``livers[template]``, or a Geometry of its own) onto every
    liver and run the PCA of the displacements of the template's surface nodes (the
    template's interior is not constrained by a surface registration, so it takes no part).
    ``known``: registrations already made, by geometry id (the file population's).
    """
    M = livers[template] if isinstance(template, int) else template
    Y = surface_samples(M, n_points)
    S = M.points[M.surface_nodes]
    morph = SurfaceMorph(M.points, M.cells, M.surface_nodes)
    disp, err, its, inv, jac = [], [], [], [], []
    for r, g in enumerate(livers):
        reg = (known or {}).get(g.geometry_id) or register(
            morph, Y, M.surface_triangles, surface_samples(g, n_points), surface_points(g),
            schedule)
        disp.append((reg.points[M.surface_nodes] - S).ravel())
        err.append(reg.residual)
        its.append(reg.iterations)
        inv.append(reg.inverted)
        jac.append(reg.min_jacobian)
        if progress is not None:
            progress(r)
    D = np.asarray(disp)
    mean = D.mean(0)
    U, Sv, Vt = np.linalg.svd(D - mean, full_matrices=False)
    coeff = project(D, mean, Vt)
    return Population(template=M, displacements=D, mean=mean, components=Vt,
                      singular_values=Sv, coefficients=coeff,
                      registration_error=np.asarray(err), iterations=its,
                      inverted=np.asarray(inv), min_jacobian=np.asarray(jac),
                      template_member=isinstance(template, int))


def surface_points(g: Geometry, per_triangle: int = 6) -> np.ndarray:
    """Points on a liver's surface: vertices plus a barycentric grid on every triangle, so that
    nearest-point distances measure distance to the surface, not to its nodes.
    """
    return dense_surface(g.points, g.surface_triangles, per_triangle)


def dense_surface(points: np.ndarray, triangles: np.ndarray, per_triangle: int = 6):
    """The vertices of ``triangles`` plus a barycentric grid of points on each of them."""
    tri = points[triangles]
    k = per_triangle
    ab = [(i / k, j / k) for i in range(1, k) for j in range(1, k - i)]
    pts = [points[np.unique(triangles)]]
    for a, b in ab:
        pts.append((1 - a - b) * tri[:, 0] + a * tri[:, 1] + b * tri[:, 2])
    return np.concatenate(pts)
