"""Pictures of deformed livers for fem_sim's summary and ``make docs``:
pyvista renders (off-screen) through :mod:`liverviz.pictures`, the drawing the surrogate's
viewer uses too.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from liverviz.pictures import Panel, Surface, render_panels


def render_shards(items, out_png: str | Path, title: str = "", cols: int | None = None) -> Path:
    """items: list of (Geometry, displacement (n_nodes, 3) at full load, load node ids,
    forces (n_loads, 3) in N, fixed node ids, label). One panel each, one colour range for all.
    """
    f_ref = max(float(np.linalg.norm(f, axis=1).max()) for _, _, _, f, _, _ in items) or 1.0
    panels = []
    for g, u, loads, forces, fixed, label in items:
        s = Surface.from_mesh(g.points, g.surface_triangles, fixed)
        panels.append(Panel(surface=s, u=np.asarray(u)[s.nodes], forces=forces,
                            load_nodes=np.asarray(loads), label=label, f_ref=f_ref))
    return render_panels(panels, out_png, title=title, cols=cols)

