"""Solver benchmark: seconds per simulation and Newton iterations per load step on a ~15k-node
liver, side by side with the textbook dolfinx approach on the same mesh and loads.

Textbook = dolfinx NewtonSolver (full Newton from the previous step, no line search), the Ogden
energy written in UFL with closed-form eigenvalues of C-bar (1e-8 symmetric perturbation to
separate equal eigenvalues), one-point quadrature, PETSc's default direct LU through MUMPS.
Ours = fem_sim.OgdenProblem with its defaults on one rank (float32 LDL^T with METIS ordering
refined by GMRES, Hermite predictor through converged states and tangents, chord steps with
the last factorisation between Newton steps, compiled point kernel and P1 assembly), with the
same residual tolerance as the textbook run. "Newton its" = factorisations for both solvers
(ours include the factorisations, if any, for the tangents at converged states); ours also
does chord steps (one back-solve and one residual each), counted separately.

    .venv-solver/bin/python bench/bench_solver.py [--mesh sofa|phantom] [--h 4.2] [--runs 3]

Prints a table (median of --runs runs) and the speed-up ratio; checks that both give the same
displacement (largest relative difference over the load steps <= 1e-6).
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
from fem_sim.solver import dolfinx_compat as dc

SOFA = Path(__file__).resolve().parents[2] / "shared" / "data" / "livers" / "sofa_liver.vtk"


def textbook_simulation(g, fixed, node, force, mat, fractions):
    """The textbook approach (see module docstring). Returns (u at nodes per step, its, secs)."""
    from dolfinx import fem, nls
    from dolfinx.fem.petsc import NonlinearProblem

    comm = MPI.COMM_WORLD
    t0 = time.perf_counter()
    msh = dc.create_mesh(comm, g.points, g.cells)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    u, v = fem.Function(V), ufl.TestFunction(V)
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
    W = c / m**2 * (l1 ** (m / 2) + l2 ** (m / 2) + l3 ** (m / 2) - 3) \
        + mat.K / 2 * ufl.ln(J) ** 2
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


def our_simulation(g, fixed, node, force, mat, fractions):
    t0 = time.perf_counter()
    prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=1,
                        settings={"rtol": 1e-10, "atol": 1e-12})
    t_setup = time.perf_counter() - t0
    t1 = time.perf_counter()
    sol = prob.solve(mat, [Constraint(fixed)], [NodalLoad([node], [force])], fractions)
    assert sol.status == "ok", sol.failure_reason
    return sol.displacement, sol.newton_iterations, time.perf_counter() - t1, t_setup, sol


def load_mesh(kind: str, h: float):
    if kind == "sofa":
        from fem_sim.geometry.surfaces import mesh_surface_file

        return mesh_surface_file(SOFA, h), "sofa_liver.vtk"
    from fem_sim.geometry.phantom import make_phantom

    return make_phantom(0, h), "phantom seed 0"


def main():
    logging.getLogger().setLevel(logging.WARNING)
    ap = argparse.ArgumentParser()
    ap.add_argument("--mesh", choices=["sofa", "phantom"], default="sofa" if SOFA.exists()
                    else "phantom")
    ap.add_argument("--h", type=float, default=None, help="mesh size, mm")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    h = args.h or (4.0 if args.mesh == "sofa" else 4.2)
    g, name = load_mesh(args.mesh, h)
    fixed = g.regions.get("vena_cava")
    if fixed is None or fixed.size == 0:
        raise SystemExit(f"{name}: no vena_cava region")
    surf = np.setdiff1d(g.surface_nodes, fixed)
    dist = np.linalg.norm(g.points[surf][:, None] - g.points[fixed][None], axis=2).min(axis=1)
    node = int(surf[np.argmax(dist)])  # far from the fixed region
    force = np.array([0.0, 0.0, -0.4])  # 0.4 N, nominal
    mat = OgdenMaterial((4.1e-3,), (10.06,), 100 * 4.1e-3)
    fr = np.linspace(0.1, 1.0, 10)
    print(f"mesh: {name}, h = {h} mm, {g.n_nodes} nodes, {g.cells.shape[0]} tets, "
          f"{fixed.size} fixed nodes; force 0.4 N on node {node}; 10 load steps; "
          f"{MPI.COMM_WORLD.size} rank(s)")
    rows = {"textbook": [], "fem_sim": []}
    for run in range(args.runs):
        u_tb, its_tb, t_tb, s_tb = textbook_simulation(g, fixed, node, force, mat, fr)
        rows["textbook"].append((t_tb, s_tb, its_tb, 0, sum(its_tb)))
        u_us, its_us, t_us, s_us, sol = our_simulation(g, fixed, node, force, mat, fr)
        rows["fem_sim"].append((t_us, s_us, its_us, sol.chord_steps, sol.factorizations))
        diff = max(np.linalg.norm(a - b) / np.linalg.norm(b) for a, b in zip(u_us, u_tb))
        print(f"run {run + 1}: textbook {t_tb:.1f} s ({sum(its_tb)} its), fem_sim {t_us:.1f} s "
              f"({sum(its_us)} its, {sol.factorizations} factorisations, {sol.chord_steps} "
              f"chord steps), "
              f"relative difference {diff:.2e}, max |u| {np.abs(u_tb[-1]).max():.2f} mm")
    print()
    print("| solver | s / simulation (median) | set-up s | Newton iterations per step "
          "| factorisations | chord steps |")
    print("|---|---|---|---|---|---|")
    med = {}
    for k, v in rows.items():
        t = np.median([x[0] for x in v])
        med[k] = t
        its = v[0][2]
        print(f"| {k} | {t:.2f} | {np.median([x[1] for x in v]):.2f} | "
              f"{' '.join(str(i) for i in its)} | {v[0][4]} | {v[0][3]} |")
    print(f"\nspeed-up (textbook / fem_sim, solve time per simulation): "
          f"{med['textbook'] / med['fem_sim']:.2f}x; same answer: relative difference "
          f"{diff:.1e} (<= 1e-6 required)")


if __name__ == "__main__":
    main()
