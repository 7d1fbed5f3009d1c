"""The solver: one Ogden body on one mesh, load-stepped (see :mod:`fem_sim.solver.problem`)."""
