"""Pictures of deformed livers (matplotlib, off-screen): the surface at full load, coloured by
displacement magnitude, with the undeformed outline and the load points.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


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
        lo, hi = g.points.min(axis=0) - 10, g.points.max(axis=0) + 10
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.view_init(25, -60)
        ax.set_title(label, fontsize=9)
        ax.set_axis_off()
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap="viridis"), ax=fig.axes, shrink=0.6,
                 label="|u| (mm)")
    if title:
        fig.suptitle(title)
    fig.savefig(out_png, dpi=90)
    plt.close(fig)
    return Path(out_png)
