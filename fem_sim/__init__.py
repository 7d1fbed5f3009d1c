"""fem_sim: MPI-parallel dolfinx solver for the Ogden liver and the scene-driven batch generator.

Importing the package does not import dolfinx; the solver classes load it on first use.
"""

from fem_sim.ogden import OgdenMaterial, ogden_point_kernel

__all__ = ["Constraint", "NodalLoad", "OgdenMaterial", "OgdenProblem", "PatchLoad", "Solution",
           "ogden_point_kernel"]


def __getattr__(name):
    if name in ("Constraint", "NodalLoad", "OgdenProblem", "PatchLoad", "Solution"):
        from fem_sim import problem

        return getattr(problem, name)
    raise AttributeError(name)
