"""Scene 4's shape parametrisation (the reference paper's section 2.4.2): non-rigid Coherent
Point Drift (CPD) of a template liver onto every liver of a population, PCA of the template's
displacement fields, and the shape coefficients of every liver.

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
* PCA: each liver r gives D_r = M_r - M (template nodes, flattened); the population's mean
  displacement and principal components come from an SVD; a liver's first n coefficients are
  its projections. A liver reconstructed from n components is the template mesh moved by
  mean + sum of n components; IoU and Dice against the liver itself (voxelised, 1.5 mm) show
  how much shape n components keep (the paper's Figure 9).

Vectorised numpy; one registration of 600 to 600 points takes about a second (see
``bench/bench_population.py``). Runs on one process, before any MPI work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from data_spec.geometry import Geometry
from fem_sim.geometry.voxels import voxelize_surface

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
            P = np.exp(-_sqdist(T, x) / (2.0 * sigma2))
            c = (2.0 * math.pi * sigma2) ** (d / 2) * w / (1.0 - w) * m / n if w > 0 else 0.0
            den = P.sum(0) + c
            den[den == 0] = np.finfo(float).tiny
            P /= den
            P1, Pt1 = P.sum(1), P.sum(0)
            Np = P1.sum()
            PX = P @ x
            # M-step: (diag(P1) G + lam sigma2 I) W = PX - diag(P1) Ys
            A = P1[:, None] * G
            A[np.diag_indices(m)] += lam * sigma2
            W = np.linalg.solve(A, PX - P1[:, None] * Ys)
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


def build_population(livers: list[Geometry], template: int = 0, n_points: int = 600,
                     schedule=STAGED, progress=None) -> Population:
    """Register the template (``livers[template]``) onto every liver and run the PCA of the
    displacements of the template's surface nodes (the template's interior is not constrained
    by a surface registration, so it takes no part).
    """
    M = livers[template]
    Y = surface_samples(M, n_points)
    S = M.points[M.surface_nodes]
    dense = surface_points(M)
    disp, err, its = [], [], []
    for r, g in enumerate(livers):
        X = surface_samples(g, n_points)
        res = cpd_nonrigid(X, Y, schedule)
        moved = res.transform(S)
        disp.append((moved - S).ravel())
        err.append(chamfer(res.transform(dense), surface_points(g)))
        its.append(res.iterations)
        if progress is not None:
            progress(r)
    D = np.asarray(disp)
    mean = D.mean(0)
    U, Sv, Vt = np.linalg.svd(D - mean, full_matrices=False)
    coeff = (D - mean) @ Vt.T
    return Population(template=M, displacements=D, mean=mean, components=Vt,
                      singular_values=Sv, coefficients=coeff,
                      registration_error=np.asarray(err), iterations=its)


def overlap(a_points, a_tris, b_points, b_tris, voxel: float = 1.5) -> tuple[float, float]:
    """(IoU, Dice) of the solids bounded by two closed surfaces, voxelised at ``voxel`` mm."""
    allp = np.concatenate([a_points, b_points])
    lo, hi = allp.min(0) - 2 * voxel, allp.max(0) + 2 * voxel
    shape = tuple(np.ceil((hi - lo) / voxel).astype(int) + 1)
    a, _ = voxelize_surface(a_points, a_tris, voxel, lo, shape)
    b, _ = voxelize_surface(b_points, b_tris, voxel, lo, shape)
    inter, union = np.logical_and(a, b).sum(), np.logical_or(a, b).sum()
    return float(inter / union), float(2 * inter / (a.sum() + b.sum()))


def surface_points(g: Geometry, per_triangle: int = 6) -> np.ndarray:
    """Points on a liver's surface: vertices plus a barycentric grid on every triangle, so that
    nearest-point distances measure distance to the surface, not to its nodes.
    """
    tri = g.points[g.surface_triangles]
    k = per_triangle
    ab = [(i / k, j / k) for i in range(1, k) for j in range(1, k - i)]
    pts = [g.points[g.surface_nodes]]
    for a, b in ab:
        pts.append((1 - a - b) * tri[:, 0] + a * tri[:, 1] + b * tri[:, 2])
    return np.concatenate(pts)


def report(pop: Population, livers: list[Geometry], n_values, voxel: float = 1.5,
           livers_for_overlap=None) -> list[dict]:
    """Per n: cumulative explained variance, mean/min IoU and Dice of the reconstructions."""
    ev = np.cumsum(pop.explained_variance_ratio)
    which = range(len(livers)) if livers_for_overlap is None else livers_for_overlap
    tris = pop.surface_triangles()
    out = []
    for n in n_values:
        iou, dice = [], []
        for r in which:
            g = livers[r]
            a, b = overlap(g.points, g.surface_triangles, pop.reconstruct(r, n), tris, voxel)
            iou.append(a)
            dice.append(b)
        out.append({"n": int(n), "explained_variance": float(ev[min(n, ev.size) - 1]),
                    "iou_mean": float(np.mean(iou)), "iou_min": float(np.min(iou)),
                    "dice_mean": float(np.mean(dice)), "dice_min": float(np.min(dice))})
    return out


def write_report(rows: list[dict], pop: Population, out_dir, title: str,
                 extra_lines=()) -> None:
    """population.md (table), population.json and population.png (the paper's Figure 9)."""
    import json
    from pathlib import Path

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = [f"# {title}", "", *extra_lines, "",
             "| n components | cumulative explained variance | IoU mean | IoU min | Dice mean "
             "| Dice min |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['n']} | {r['explained_variance']:.4f} | {r['iou_mean']:.4f} | "
                     f"{r['iou_min']:.4f} | {r['dice_mean']:.4f} | {r['dice_min']:.4f} |")
    (out_dir / "population.md").write_text("\n".join(lines) + "\n")
    (out_dir / "population.json").write_text(json.dumps({
        "rows": rows, "registration_error_mm": pop.registration_error.tolist(),
        "explained_variance_ratio": pop.explained_variance_ratio.tolist()}, indent=1))
    plot_report(rows, out_dir / "population.png", title)


def plot_report(rows: list[dict], png, title: str) -> None:
    """Explained variance, IoU and Dice against the number of components (Figure 9)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["n"] for r in rows]
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.plot(n, [r["explained_variance"] for r in rows], "k-o", ms=3, label="explained variance")
    ax.plot(n, [r["iou_mean"] for r in rows], "b-s", ms=3, label="IoU (mean)")
    ax.plot(n, [r["dice_mean"] for r in rows], "r-^", ms=3, label="Dice (mean)")
    ax.plot(n, [r["iou_min"] for r in rows], "b:", lw=1, label="IoU (worst liver)")
    ax.set_xlabel("PCA components")
    ax.set_ylim(0.0, 1.0)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def attach_shape_coefficients(livers: list[Geometry], n_components: int, cache=None,
                              n_points: int = 600, progress=None) -> Population | None:
    """Set ``shape_coefficients`` (first ``n_components`` PCA coefficients) on every liver.

    ``cache``: an ``.npz`` path; reused when it was made for the same livers (geometry ids),
    written otherwise. Returns the Population when it was computed, None when cached.
    """
    from pathlib import Path

    if n_components > len(livers) - 1:
        raise ValueError(f"pca_components = {n_components} needs at least {n_components + 1} "
                         f"livers, the population has {len(livers)}")
    ids = np.array([g.geometry_id for g in livers])
    if cache is not None and Path(cache).exists():
        with np.load(cache, allow_pickle=False) as z:
            if np.array_equal(z["geometry_ids"], ids) and z["coefficients"].shape[1] >= \
                    n_components:
                for g, c in zip(livers, z["coefficients"]):
                    g.shape_coefficients = c[:n_components].copy()
                return None
    pop = build_population(livers, 0, n_points, progress=progress)
    set_coefficients(livers, pop, n_components)
    if cache is not None:
        save_population(cache, livers, pop)
    return pop


def set_coefficients(livers: list[Geometry], pop: Population, n_components: int) -> None:
    """Each liver's first ``n_components`` PCA coefficients, as its ``shape_coefficients``."""
    for g, c in zip(livers, pop.coefficients):
        g.shape_coefficients = c[:n_components].copy()


def save_population(path, livers: list[Geometry], pop: Population) -> None:
    """The PCA (and the geometry ids it belongs to) as an .npz, written atomically."""
    from data_spec.atomic import atomic_path

    with atomic_path(path) as tmp, open(tmp, "wb") as f:  # a file object: no ".npz" appended
        np.savez(f, geometry_ids=np.array([g.geometry_id for g in livers]),
                 coefficients=pop.coefficients, mean=pop.mean, components=pop.components,
                 singular_values=pop.singular_values,
                 registration_error=pop.registration_error)
