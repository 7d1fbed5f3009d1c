"""docs/phantoms.png: six livers of the embedded phantom population (seeds 0-5) at 8 mm, each
deformed by 0.4 N on the surface node farthest from the vena-cava region (fixed, blue),
pressed downward (-z), the default material, P1 in 10 load steps: what a scene-1 simulation
does to each. Regenerate with ``make docs`` (about half a minute on 2 cores).

The solves and the picture run in two processes: VTK's wheel must not share a process with
dolfinx (see liverviz.pictures).
"""

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

FORCE = np.array([[0.0, 0.0, -0.4]])  # N
TITLE = ("fem_sim phantom livers: 0.4 N pressing down on the node farthest from the vena-cava "
         "region (blue, fixed)")


def solve(work: Path) -> None:
    from mpi4py import MPI

    from data_spec import write_geometry
    from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
    from fem_sim.geometry.phantom import make_phantom, mesh_volume

    for seed in range(6):
        g = make_phantom(seed, 8.0)
        fixed = g.regions["vena_cava"]
        surf = g.surface_nodes
        gap = np.min(np.linalg.norm(g.points[surf][:, None] - g.points[fixed][None], axis=2), 1)
        node = int(surf[np.argmax(gap)])
        prob = OgdenProblem(MPI.COMM_SELF, g.points, g.cells, degree=1)
        sol = prob.solve(OgdenMaterial((4.1e-3,), (10.06,), 100 * 4.1e-3), [Constraint(fixed)],
                         [NodalLoad([node], FORCE)], [k / 10 for k in range(1, 11)])
        u = sol.displacement[-1]
        ext = g.points.max(0) - g.points.min(0)
        label = (f"seed {seed}: {mesh_volume(g) / 1e6:.2f} L, {ext[0]:.0f} x {ext[1]:.0f} x "
                 f"{ext[2]:.0f} mm, {g.n_nodes} nodes\nmax displacement "
                 f"{np.linalg.norm(u, axis=1).max():.1f} mm")
        write_geometry(work / f"g{seed}.h5", g)
        np.savez(work / f"u{seed}.npz", u=u, node=node, fixed=fixed, label=label)
        print(f"seed {seed}: {g.n_nodes} nodes, max |u| {np.linalg.norm(u, axis=1).max():.1f} mm",
              flush=True)


def render(work: Path, out: Path) -> None:
    from data_spec import read_geometry
    from fem_sim.render import render_shards

    items = []
    for seed in range(6):
        z = np.load(work / f"u{seed}.npz")
        items.append((read_geometry(work / f"g{seed}.h5"), z["u"], [int(z["node"])], FORCE,
                      z["fixed"], str(z["label"])))
    render_shards(items, out, TITLE, cols=3)
    print(out)


if __name__ == "__main__":
    if sys.argv[1:2] == ["--render"]:
        render(Path(sys.argv[2]), Path(sys.argv[3]))
    else:
        target = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/phantoms.png")
        with tempfile.TemporaryDirectory() as tmp:
            solve(Path(tmp))
            subprocess.run([sys.executable, __file__, "--render", tmp, str(target)], check=True)
