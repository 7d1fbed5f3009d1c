"""A liver's Green's function on request, for ``fem_sim serve``.

``make liver`` solves the unit responses of the nodes its load needs only; the manipulator
grasps anywhere. A solver process opened on the liver's data directory keeps the liver's
tangent at rest and its float64 factorisation, and answers a new patch's unit responses by
back-solves alone (the rows ``fem_sim linear --green`` gives, solved as a smaller block)::

    ["green-open", DATA]                  the liver of make liver's data directory
    ["green-rows", OUT.npy, NODE, ...]    (k, 3, n_out, 3) float32 mm/N into OUT.npy
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


class LiveGreen:
    """The liver of the one-liver data directory ``data`` (its scene, mesh and small-strain
    file with a Green's function), factorised: :meth:`rows` gives unit responses.
    """

    def __init__(self, data: str | Path):
        from mpi4py import MPI

        from data_spec import load_scene, read_geometry
        from data_spec.linear_fields import read_dataset_linear
        from data_spec.shards import geometry_path
        from fem_sim.batch.generate import solver_settings
        from fem_sim.batch.linear import _cases
        from fem_sim.solver.loads import Constraint
        from fem_sim.solver.problem import OgdenProblem

        data = Path(data)
        lf = read_dataset_linear(data)
        if lf.green is None:
            raise ValueError(f"{data}: its small-strain file holds no Green's function (fem_sim "
                             "linear --green)")
        scene = load_scene(data / "scene.toml")
        g = read_geometry(geometry_path(data, lf.geometry_id))
        fixed = lf.fixed(g.surface_nodes)
        material = _cases(scene, str(data / "scene.toml"), g, fixed, 0)[0].material
        solver = scene["solver"]
        self.problem = OgdenProblem(MPI.COMM_SELF, g.points, g.cells, degree=solver["degree"],
                                    quadrature_degree=solver["quadrature_degree"],
                                    element=solver.get("element", "lagrange"),
                                    settings=solver_settings(scene))
        self.J = self.problem.tangent_at_rest(material, [Constraint(fixed)])
        self.free, self.columns = np.setdiff1d(g.surface_nodes, fixed), lf.output_nodes
        self.rows(self.free[:1])   # the factorisation, once

    def rows(self, nodes) -> np.ndarray:
        """(k, 3, n_out, 3) float32 mm/N: the unit responses at the free surface ``nodes``
        along x, y, z at the file's output nodes; ValueError naming a node off it.
        """
        nodes = np.asarray(nodes, dtype=np.int64).ravel()
        off = np.setdiff1d(nodes, self.free)
        if off.size:
            raise ValueError(f"node {int(off[0])} is not on the free surface (fixed or inside)")
        u = self.problem.unit_responses_of(self.J, nodes)
        return u[:, :, self.columns].astype(np.float32)


def serve_verb(live: LiveGreen | None, words: list[str]) -> tuple[LiveGreen | None, int]:
    """Run ``green-open`` or ``green-rows`` (``words``): (the live liver, exit code)."""
    import sys

    try:
        if words[0] == "green-open" and len(words) == 2:
            return LiveGreen(words[1]), 0
        if words[0] == "green-rows" and len(words) >= 3:
            if live is None:
                raise ValueError("green-rows before green-open")
            np.save(words[1], live.rows([int(w) for w in words[2:]]))
            return live, 0
        raise ValueError(f"expected green-open DATA or green-rows OUT.npy NODE..., got {words}")
    except (ValueError, OSError, KeyError) as exc:
        print(f"fem_sim serve: {words[0]}: {exc}", file=sys.stderr)
        return live, 2
