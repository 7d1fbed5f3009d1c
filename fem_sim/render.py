"""Pictures of deformed livers (matplotlib, off-screen): the surface at full load, coloured by
displacement magnitude, with the undeformed outline and the load points.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _frame(ax, lo, hi, view, label: str) -> None:
    """Equal-aspect 3-D axes over the box [lo, hi], seen from (elevation, azimuth) ``view``."""
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo)
    ax.view_init(*view)
    ax.set_title(label, fontsize=9)
    ax.set_axis_off()


def render_shards(items, out_png: str | Path, title: str = "") -> Path:
    """items: list of (Geometry, displacement (n_nodes, 3) at full load, load node ids, label)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import cm, colors
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    n = len(items)
    fig = plt.figure(figsize=(5 * n, 4.6))
    vmax = max(float(np.linalg.norm(u, axis=1).max()) for _, u, _, _ in items) or 1.0
    norm = colors.Normalize(0.0, vmax)
    for k, (g, u, loads, label) in enumerate(items):
        ax = fig.add_subplot(1, n, k + 1, projection="3d")
        x = g.points + u
        tri = g.surface_triangles
        mag = np.linalg.norm(u, axis=1)[tri].mean(axis=1)
        poly = Poly3DCollection(x[tri], facecolors=cm.viridis(norm(mag)), edgecolor="none")
        ax.add_collection3d(poly)
        ref = g.points[g.surface_nodes[:: max(1, g.surface_nodes.size // 400)]]
        ax.scatter(*ref.T, s=0.3, c="0.6")
        fixed = g.regions.get("vena_cava")
        if fixed is not None and fixed.size:
            ax.scatter(*x[fixed].T, s=3, c="k")
        ax.scatter(*x[np.asarray(loads)].T, s=40, c="r", marker="v")
        _frame(ax, g.points.min(axis=0) - 10, g.points.max(axis=0) + 10, (25, -60), label)
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap="viridis"), ax=fig.axes, shrink=0.6,
                 label="|u| (mm)")
    if title:
        fig.suptitle(title)
    fig.savefig(out_png, dpi=90)
    plt.close(fig)
    return Path(out_png)


def render_geometries(items, out_png: str | Path, title: str = "") -> Path:
    """items: list of (Geometry, label). Shaded surfaces with the vena-cava region in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    n = len(items)
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    fig = plt.figure(figsize=(4.4 * cols, 3.6 * rows))
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    for k, (g, label) in enumerate(items):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        x = g.points
        tri = g.surface_triangles
        nrm = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        shade = 0.35 + 0.65 * np.clip(nrm @ light, 0, 1)
        base = np.tile([0.72, 0.42, 0.36], (tri.shape[0], 1))
        fixed = g.regions.get("vena_cava")
        if fixed is not None and fixed.size:
            on = np.isin(tri, fixed).all(axis=1)
            base[on] = [0.25, 0.35, 0.8]
        ax.add_collection3d(Poly3DCollection(x[tri], facecolors=base * shade[:, None],
                                             edgecolor="none"))
        _frame(ax, x.min(axis=0), x.max(axis=0), (35, 70), label)  # from behind: vena cava
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out_png, dpi=70)
    plt.close(fig)
    return Path(out_png)
