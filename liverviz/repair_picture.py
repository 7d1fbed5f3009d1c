"""A liver's repair at a glance (matplotlib, no OpenGL): the input surface with its open
edges in red, the meshed liver's surface, and the tetrahedra's smallest dihedral angles.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _surface(ax, points, tris, colour: str, title: str) -> None:
    ax.plot_trisurf(points[:, 0], points[:, 1], points[:, 2], triangles=tris, color=colour,
                    linewidth=0.05, edgecolor="0.3", alpha=0.9, shade=True)
    ax.set_title(title, fontsize=9)
    lo, hi = points.min(axis=0), points.max(axis=0)
    c, r = (lo + hi) / 2, (hi - lo).max() / 2
    for set_lim, k in ((ax.set_xlim, 0), (ax.set_ylim, 1), (ax.set_zlim, 2)):
        set_lim(c[k] - r, c[k] + r)
    ax.set_axis_off()


def repair_picture(png, input_points, input_tris, open_edges, mesh_points, mesh_tris,
                   min_dihedral: np.ndarray, summary: str) -> Path:
    """Three panels into ``png``: input (open edges red), meshed surface, the histogram of
    each tetrahedron's smallest dihedral angle; ``summary`` as the title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(13, 4.6))
    ax = fig.add_subplot(1, 3, 1, projection="3d")
    _surface(ax, input_points, input_tris, "0.8", f"input: {len(input_tris):,} triangles, "
             f"{len(open_edges):,} open edges (red)")
    for a, b in open_edges:
        ax.plot(*input_points[[a, b]].T, color="red", lw=1.2)
    ax = fig.add_subplot(1, 3, 2, projection="3d")
    _surface(ax, mesh_points, mesh_tris, "#c98f7a", f"meshed: {len(mesh_tris):,} boundary "
             "triangles")
    ax = fig.add_subplot(1, 3, 3)
    ax.hist(min_dihedral, bins=60, color="0.4")
    ax.axvline(min_dihedral.min(), color="red", lw=1)
    ax.set_xlabel("smallest dihedral angle of each tetrahedron (degrees)")
    ax.set_ylabel("tetrahedra")
    ax.set_title(f"mesh quality: smallest {min_dihedral.min():.1f} degrees", fontsize=9)
    fig.suptitle(summary, fontsize=9)
    fig.tight_layout()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=100)
    plt.close(fig)
    return png
