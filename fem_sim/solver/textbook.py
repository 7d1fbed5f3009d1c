"""The textbook dolfinx solver: the baseline fem_sim's solver is measured against.

dolfinx's NewtonSolver (full Newton from the previous load step, no line search) on the Ogden
energy written in UFL with closed-form eigenvalues of C-bar (a 1e-8 symmetric perturbation
separates equal eigenvalues), one-point quadrature (FEBio's tet4), and PETSc's direct LU
through MUMPS: what a user would script from the dolfinx demos. bench/bench_hard.py runs it side
by side with :class:`fem_sim.OgdenProblem` on the same mesh and load (same answer, seconds and
factorisations). P1 and a nodal load only.
"""

from __future__ import annotations

import time

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from fem_sim.solver import dolfinx_compat as dc


def ufl_ogden_energy(u, mat):
    """The uncoupled one-term Ogden energy density of the displacement ``u`` in UFL: the
    principal stretches from the closed-form eigenvalues of C-bar (trigonometric formula), a
    1e-8 symmetric perturbation separating equal eigenvalues, K/2 (ln J)^2.
    """
    d = 3
    F = ufl.Identity(d) + ufl.grad(u)
    J = ufl.det(F)
    C = F.T * F
    Cb = J ** (-2.0 / 3.0) * C + 1e-8 * ufl.as_matrix([[0, 1, 0], [1, 0, 1], [0, 1, 0]])
    q = ufl.tr(Cb) / 3
    p1 = Cb[0, 1] ** 2 + Cb[0, 2] ** 2 + Cb[1, 2] ** 2
    p2 = (Cb[0, 0] - q) ** 2 + (Cb[1, 1] - q) ** 2 + (Cb[2, 2] - q) ** 2 + 2 * p1
    p = ufl.sqrt(p2 / 6)
    B = (Cb - q * ufl.Identity(d)) / p
    r = ufl.det(B) / 2
    r = ufl.max_value(ufl.min_value(r, 1.0 - 1e-14), -1.0 + 1e-14)
    phi = ufl.acos(r) / 3
    l1 = q + 2 * p * ufl.cos(phi)
    l3 = q + 2 * p * ufl.cos(phi + 2 * np.pi / 3)
    l2 = 3 * q - l1 - l3
    c, m = mat.c[0], mat.m[0]
    return c / m**2 * (l1 ** (m / 2) + l2 ** (m / 2) + l3 ** (m / 2) - 3) \
        + mat.K / 2 * ufl.ln(J) ** 2


def textbook_simulation(g, fixed, node, force, mat, fractions):
    """One simulation the textbook way on the mesh ``g`` (points, cells), fixed at the nodes
    ``fixed``, the nodal force ``force`` (N) on node ``node`` scaled by each of ``fractions``.
    Returns (u at the mesh's nodes per step (one rank; None per step on several), Newton
    iterations per step, seconds of the steps, seconds of the set-up).
    """
    from dolfinx import fem, nls
    from dolfinx.fem.petsc import NonlinearProblem

    comm = MPI.COMM_WORLD
    t0 = time.perf_counter()
    msh = dc.create_mesh(comm, g.points, g.cells)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    u, v = fem.Function(V), ufl.TestFunction(V)
    W = ufl_ogden_energy(u, mat)
    dx = ufl.dx(metadata={"quadrature_degree": 1})
    R = ufl.derivative(W * dx, u, v)
    blocks, src = dc.vertex_dof_source_ids(msh, V)
    s2b = dict(zip(src.tolist(), blocks.tolist()))
    fixed_blocks = np.array(sorted(s2b[n] for n in fixed if n in s2b), dtype=np.int32)
    bc = fem.dirichletbc(np.zeros(3, dtype=PETSc.ScalarType), fixed_blocks, V)
    lam = fem.Constant(msh, PETSc.ScalarType(0.0))
    load_blk = s2b.get(int(node))

    class PointLoadProblem(NonlinearProblem):
        def F(self, x, b):
            super().F(x, b)
            if load_blk is not None and load_blk < V.dofmap.index_map.size_local:
                b.array[3 * load_blk: 3 * load_blk + 3] -= float(lam.value) * force

    problem = PointLoadProblem(R, u, bcs=[bc], form_compiler_params={},
                               jit_params={})
    solver = nls.petsc.NewtonSolver(comm, problem)
    solver.rtol, solver.atol, solver.max_it = 1e-10, 1e-12, 50
    solver.convergence_criterion = "residual"
    ksp = solver.krylov_solver
    opts = PETSc.Options()
    prefix = ksp.getOptionsPrefix()
    opts[f"{prefix}ksp_type"] = "preonly"
    opts[f"{prefix}pc_type"] = "lu"
    opts[f"{prefix}pc_factor_mat_solver_type"] = "mumps"
    ksp.setFromOptions()
    t_setup = time.perf_counter() - t0
    its, out = [], []
    t1 = time.perf_counter()
    for fr in fractions:
        lam.value = fr
        n, ok = solver.solve(u)
        its.append(n)
        vals = u.x.array.reshape(-1, 3)
        out.append(vals[blocks][np.argsort(src)].copy() if comm.size == 1 else None)
    return np.array(out), its, time.perf_counter() - t1, t_setup
