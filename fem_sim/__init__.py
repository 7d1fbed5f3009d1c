"""fem_sim: MPI-parallel dolfinx solver for the Ogden liver and the scene-driven batch generator."""
