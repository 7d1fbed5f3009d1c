"""Scene 4's population on the solver side: shape coefficients attached to a scene's livers
(cached next to the dataset), and the population report (the paper's Figure 9: explained
variance, IoU and Dice of the reconstructions). The registration and the PCA themselves are
:mod:`liverreg.cpd` (numpy and scipy only, shared with the trainer).
"""

from __future__ import annotations

import numpy as np

from data_spec.geometry import Geometry
from fem_sim.geometry.voxels import voxelize_surface
from liverreg.cpd import (  # noqa: F401  (re-exported: the population's vocabulary)
    PLAIN,
    STAGED,
    CPDResult,
    Population,
    build_population,
    chamfer,
    cpd_nonrigid,
    farthest_points,
    project,
    surface_points,
    surface_samples,
)


def overlap(a_points, a_tris, b_points, b_tris, voxel: float = 1.5) -> tuple[float, float]:
    """(IoU, Dice) of the solids bounded by two closed surfaces, voxelised at ``voxel`` mm."""
    allp = np.concatenate([a_points, b_points])
    lo, hi = allp.min(0) - 2 * voxel, allp.max(0) + 2 * voxel
    shape = tuple(np.ceil((hi - lo) / voxel).astype(int) + 1)
    a, _ = voxelize_surface(a_points, a_tris, voxel, lo, shape)
    b, _ = voxelize_surface(b_points, b_tris, voxel, lo, shape)
    inter, union = np.logical_and(a, b).sum(), np.logical_or(a, b).sum()
    return float(inter / union), float(2 * inter / (a.sum() + b.sum()))


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
                              n_points: int = 600, progress=None, template=0, known=None,
                              region: str = "vena_cava") -> Population | None:
    """Set ``shape_coefficients`` (first ``n_components`` PCA coefficients) on every liver.

    ``cache``: an ``.npz`` path; reused when it was made for the same livers (geometry ids),
    written otherwise. Returns the Population when it was computed, None when cached.
    ``template``, ``known``: :func:`liverreg.cpd.build_population`'s; ``region``: the
    template's fixed region, kept with a template that is not one of the livers.
    """
    from pathlib import Path

    if n_components > len(livers) - 1:
        raise ValueError(f"pca_components = {n_components} needs at least {n_components + 1} "
                         f"livers, the population has {len(livers)}")
    ids = np.array([g.geometry_id for g in livers])
    known = dict(known or {})
    M = livers[template] if isinstance(template, int) else template
    key = registration_key(M, n_points)
    if cache is not None and Path(cache).exists():
        with np.load(cache, allow_pickle=False) as z:
            if np.array_equal(z["geometry_ids"], ids) and z["coefficients"].shape[1] >= \
                    n_components:
                for g, c in zip(livers, z["coefficients"]):
                    g.shape_coefficients = c[:n_components].copy()
                return None
            known = {**cached_registrations(z, M, key), **known}
    pop = build_population(livers, template, n_points, progress=progress, known=known)
    set_coefficients(livers, pop, n_components)
    if cache is not None:
        save_population(cache, livers, pop, region, key)
    return pop


def registration_key(template: Geometry, n_points: int) -> str:
    """What a liver's registration depends on besides the liver: the template's mesh, the
    samples and the registration code (liverreg's cpd and morph).
    """
    import hashlib
    from pathlib import Path

    from liverreg import cpd, morph

    h = hashlib.sha256(template.content_hash.encode() + str(n_points).encode())
    for module in (cpd, morph):
        h.update(Path(module.__file__).read_bytes())
    return h.hexdigest()[:16]


def cached_registrations(z, template: Geometry, key: str) -> dict:
    """The registrations an earlier population holds (an open population.npz) when they were
    made with ``key`` (:func:`registration_key`: the same template, samples and code), by
    geometry id: a population that grows registers only its new livers. Only the template
    surface is kept there, which is what the PCA reads.
    """
    from liverreg.cpd import Registration, surface_displacements

    if "registration_key" not in z.files or str(z["registration_key"]) != key:
        return {}
    D = surface_displacements(z)
    jac = z["min_jacobian"] if "min_jacobian" in z.files else np.ones(len(D))
    out = {}
    for gid, d, err, inv, j in zip(z["geometry_ids"], D, z["registration_error"],
                                   z["inverted"], jac):
        points = template.points.copy()
        points[template.surface_nodes] += d.reshape(-1, 3)
        out[str(gid)] = Registration(points=points, residual=float(err), inverted=int(inv),
                                     iterations=[], min_jacobian=float(j))
    return out


def set_coefficients(livers: list[Geometry], pop: Population, n_components: int) -> None:
    """Each liver's first ``n_components`` PCA coefficients, as its ``shape_coefficients``."""
    for g, c in zip(livers, pop.coefficients):
        g.shape_coefficients = c[:n_components].copy()


def save_population(path, livers: list[Geometry], pop: Population,
                    region: str = "vena_cava", key: str = "") -> None:
    """The PCA (and the geometry ids it belongs to) as an .npz, written atomically; with a
    template that is not one of the livers, the template's mesh and fixed region (``region``).
    """
    from data_spec.atomic import atomic_path

    extra = {}
    if not pop.template_member:
        T = pop.template
        extra = {"template_points": T.points, "template_cells": T.cells,
                 "template_triangles": T.surface_triangles,
                 "template_fixed": T.regions[region]}
    if pop.min_jacobian is not None:
        extra["min_jacobian"] = pop.min_jacobian
    if key:  # the registrations' key (registration_key): reused by a grown population
        extra["registration_key"] = np.array(key)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:  # a file object: no ".npz" appended
        np.savez(f, geometry_ids=np.array([g.geometry_id for g in livers]),
                 coefficients=pop.coefficients, mean=pop.mean, components=pop.components,
                 singular_values=pop.singular_values,
                 registration_error=pop.registration_error, inverted=pop.inverted, **extra)
