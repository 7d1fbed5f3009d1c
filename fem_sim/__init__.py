"""fem_sim: MPI-parallel dolfinx solver for the Ogden liver and the scene-driven batch generator.

Layout: ``material/`` (the Ogden law), ``geometry/`` (livers and meshes), ``solver/`` (one
simulation: discretisation, assembly, linear solvers, predictors, Newton, load stepping),
``batch/`` (datasets under MPI, summaries, the command line).

Importing the package does not import dolfinx; :class:`OgdenProblem` loads it on first use.
"""

from fem_sim.material.ogden import OgdenMaterial, ogden_point_kernel
from fem_sim.solver.loads import Constraint, NodalLoad, PatchLoad

__all__ = ["Constraint", "NodalLoad", "OgdenMaterial", "OgdenProblem", "PatchLoad", "Solution",
           "ogden_point_kernel"]


def __getattr__(name):
    if name in ("OgdenProblem", "Solution"):
        from fem_sim.solver import problem

        return getattr(problem, name)
    raise AttributeError(name)
