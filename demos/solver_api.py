"""The solver as a library: one simulation of the embedded liver, no batch machinery.

    .venv-solver/bin/python demos/solver_api.py
    mpirun -n 2 .venv-solver/bin/python demos/solver_api.py      # one simulation, two ranks

The mesh is given on rank 0 (the other ranks pass None); the displacement comes back on
rank 0 in the mesh's own node order, whatever the number of ranks.
"""

import numpy as np
from mpi4py import MPI

from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
from fem_sim.geometry.phantom import make_phantom

comm = MPI.COMM_WORLD
liver = make_phantom(seed=0, mesh_size=20.0) if comm.rank == 0 else None  # mm
fixed = comm.bcast(liver.regions["vena_cava"] if comm.rank == 0 else None)
node = comm.bcast(int(np.argmax(liver.points[:, 0])) if comm.rank == 0 else None)

prob = OgdenProblem(comm, liver.points if comm.rank == 0 else None,
                    liver.cells if comm.rank == 0 else None, degree=2)   # collective
material = OgdenMaterial(c=(4.1e-3,), m=(10.06,), K=0.41)            # MPa: K/mu = 200
force = [0.0, 0.0, -0.4]                                              # N
sol = prob.solve(material, [Constraint(fixed)], [NodalLoad([node], [force])],
                 fractions=[0.1 * k for k in range(1, 11)])           # collective

if comm.rank == 0:
    u = sol.displacement                        # (10 load steps, n_nodes, 3) mm
    assert sol.status == "ok", sol.failure_reason
    assert np.abs(u[:, fixed]).max() == 0.0     # the fixed region does not move
    assert u[-1, node, 2] < 0.0                 # the loaded node moves with the force
    print(f"{comm.size} rank(s): {liver.n_nodes} nodes, max |u| "
          f"{np.linalg.norm(u[-1], axis=1).max():.2f} mm at 0.4 N; "
          f"{sol.factorizations} factorisations, Newton iterations per step "
          f"{sol.newton_iterations}")
