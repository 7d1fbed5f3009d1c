"""docs/phantoms.png: six livers of the embedded phantom population (seeds 0-5), vena-cava
region in blue. Regenerate with ``make docs``.
"""

import sys
from pathlib import Path

from fem_sim.geometry.phantom import make_phantom, mesh_volume
from fem_sim.render import render_geometries

out = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/phantoms.png")
items = []
for seed in range(6):
    g = make_phantom(seed, 8.0)
    vol = mesh_volume(g) / 1e6
    ext = g.points.max(0) - g.points.min(0)
    items.append((g, f"seed {seed}: {vol:.2f} L, {ext[0]:.0f} x {ext[1]:.0f} x {ext[2]:.0f} mm, "
                     f"{g.n_nodes} nodes"))
render_geometries(items, out, "fem_sim phantom livers (blue: vena-cava region, fixed)")
print(out)
