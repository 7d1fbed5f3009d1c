"""fem_sim: MPI-parallel dolfinx solver for the Ogden liver and the scene-driven batch generator.

Layout: ``material/`` (the Ogden law), ``geometry/`` (livers and meshes), ``solver/`` (one
simulation: discretisation, assembly, linear solvers, predictors, Newton, load stepping),
``batch/`` (datasets under MPI, summaries, the command line).

Importing the package does not import dolfinx; :class:`OgdenProblem` loads it on first use.
Imported before numpy, it chooses OpenBLAS' kernels from the CPU (:mod:`fem_sim.cpu_blas`).
"""

import sys

if "numpy" not in sys.modules:  # only effective before OpenBLAS is loaded
    from fem_sim.cpu_blas import configure as _configure_blas

    _configure_blas()

from fem_sim.material.ogden import OgdenMaterial, ogden_point_kernel  # noqa: E402
from fem_sim.solver.loads import Constraint, NodalLoad, PatchLoad  # noqa: E402

__all__ = ["Constraint", "NodalLoad", "OgdenMaterial", "OgdenProblem", "PatchLoad", "Solution",
           "ogden_point_kernel"]


def __getattr__(name):
    if name in ("OgdenProblem", "Solution"):
        from fem_sim.solver import problem

        return getattr(problem, name)
    raise AttributeError(name)
