"""One Newton step's linear algebra on the real liver (or the phantom): the Jacobian assembled
by dolfinx and by fem_sim's C assembly (P1), factorised by PETSc's MUMPS LDL^T (PORD), fem_sim's
serial LDL^T (METIS) in float64 and float32, and MKL PARDISO's float32 Cholesky; at the
converged state of bench_hard.py's easy case. Prints assembly and factorisation seconds
(medians of --runs), GFlop, back-solve seconds and one solve's relative residual. Threads:
OMP_NUM_THREADS (PARDISO), OPENBLAS_NUM_THREADS (MUMPS' fronts).

    OPENBLAS_NUM_THREADS=1 .venv-solver/bin/python bench/bench_jacobian.py [--mesh sofa] [--h 5.0]
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
from fem_sim.solver import ldlt, pardiso
from fem_sim.solver.assembly import DolfinxAssembler
from liverviz.report import SOFA


def load_mesh(kind: str, h: float):
    """(geometry, its name): the real liver or the phantom of seed 0 at mesh size ``h``."""
    from fem_sim.geometry.phantom import make_phantom
    from fem_sim.geometry.repair import mesh_surface_file

    if kind == "sofa":
        return mesh_surface_file(SOFA, h), "sofa_liver.vtk"
    return make_phantom(0, h), "phantom seed 0"


def jacobian(kind: str, h: float):
    g, name = load_mesh(kind, h)
    fixed = g.regions["vena_cava"]
    surf = np.setdiff1d(g.surface_nodes, fixed)
    dist = np.linalg.norm(g.points[surf][:, None] - g.points[fixed][None], axis=2).min(axis=1)
    node = int(surf[np.argmax(dist)])
    prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=1)
    sol = prob.solve(OgdenMaterial((4.1e-3,), (10.06,), 0.41), [Constraint(fixed)],
                     [NodalLoad([node], [[0.0, 0.0, -0.4]])], np.linspace(0.1, 1.0, 10))
    assert sol.status == "ok", sol.failure_reason
    eqs = prob.equations
    eqs.update_points(tangent=True)
    eqs.residual(1.0)
    indptr, indices, values = (np.array(a) for a in eqs.jacobian(lift=False).csr())
    return name, g.n_nodes, prob, (indptr, indices, values)


def assembly(prob, runs):
    """Median seconds of dolfinx's and the C assembly (each with the constraints applied),
    and the largest entry difference relative to the largest entry."""
    reference = DolfinxAssembler(prob.disc)  # same discretisation and point values
    cons = prob.equations.cons

    def with_dolfinx():
        return reference.jacobian(cons)

    def with_c():
        return prob.assembler.jacobian(cons)

    t_d, t_c = [], []
    for _ in range(runs):
        for fn, ts in ((with_dolfinx, t_d), (with_c, t_c)):
            t = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t)
    ref = ldlt.csr(*with_dolfinx().csr())
    ours = ldlt.csr(*with_c().csr())
    diff = abs(ours - ref).max() / abs(ref).max()
    return np.median(t_d), np.median(t_c), diff


def petsc_mumps(indptr, indices, values, b, runs):
    n = indptr.size - 1
    A = PETSc.Mat().createAIJ([n, n], csr=(indptr, indices, values), comm=MPI.COMM_SELF)
    A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    A.assemble()
    ksp = PETSc.KSP().create(MPI.COMM_SELF)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("cholesky")
    pc.setFactorSolverType("mumps")
    ksp.setOperators(A, A)
    ksp.setUp()  # analysis + first factorisation
    times = []
    for _ in range(runs):
        A.assemble()
        A.shift(0.0)  # a new matrix state: the next set-up refactorises (same pattern)
        ksp.setOperators(A, A)
        t = time.perf_counter()
        ksp.setUp()
        times.append(time.perf_counter() - t)
    F = pc.getFactorMatrix()
    flops = F.getMumpsRinfog(3)
    bv, xv = A.createVecRight(), A.createVecRight()
    bv.array[:] = b
    solves = []
    for _ in range(runs):
        t = time.perf_counter()
        ksp.solve(bv, xv)
        solves.append(time.perf_counter() - t)
    return flops, np.median(times), np.median(solves), xv.array.copy()


def own(indptr, indices, values, b, runs, precision):
    solver = (pardiso.PardisoCholesky() if precision == "pardiso" else
              ldlt.SerialLDLT(precision, bs=3, pivoting=precision == "double"))
    solver.factor(indptr, indices, values)
    times, solves = [], []
    for _ in range(runs):
        t = time.perf_counter()
        solver.factor(indptr, indices, values)
        times.append(time.perf_counter() - t)
    for _ in range(runs):
        t = time.perf_counter()
        x = solver.solve(b)
        solves.append(time.perf_counter() - t)
    return solver.flops, np.median(times), np.median(solves), x


def main():
    logging.getLogger().setLevel(logging.WARNING)
    ap = argparse.ArgumentParser()
    ap.add_argument("--mesh", choices=["sofa", "phantom"], default=None)
    ap.add_argument("--h", type=float, default=5.0)
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    kind = args.mesh or ("sofa" if SOFA.exists() else "phantom")
    name, nodes, prob, (indptr, indices, values) = jacobian(kind, args.h)
    n = indptr.size - 1
    A = ldlt.csr(indptr, indices, values)
    b = np.random.default_rng(0).standard_normal(n)
    print(f"{name}, h = {args.h} mm: {nodes} nodes, {n} dofs, {indices.size} non-zeros; "
          f"median of {args.runs}, one process")
    print()
    t_d, t_c, diff = assembly(prob, args.runs)
    print("| Jacobian assembly (P1, one point, constraints applied) | s | speed-up |")
    print("|---|---|---|")
    print(f"| dolfinx assemble_matrix + zeroRowsColumns | {t_d:.3f} | 1.0x |")
    print(f"| fem_sim C assembly into the CSR pattern | {t_c:.3f} | {t_d / t_c:.1f}x |")
    print(f"\nlargest entry difference / largest entry: {diff:.1e}")
    print()
    print("| factorisation | GFlop | s / factorisation | s / back-solve | relative residual |")
    print("|---|---|---|---|---|")
    rows = [("PETSc MUMPS LDL^T, PORD", petsc_mumps(indptr, indices, values, b, args.runs)),
            ("fem_sim LDL^T, METIS, float64", own(indptr, indices, values, b, args.runs,
                                                  "double")),
            ("fem_sim LDL^T (MUMPS), METIS, float32", own(indptr, indices, values, b,
                                                          args.runs, "single"))]
    if pardiso.available():
        rows.append(("fem_sim Cholesky (MKL PARDISO, its METIS), float32",
                     own(indptr, indices, values, b, args.runs, "pardiso")))
    for label, (flops, tf, ts, x) in rows:
        res = np.linalg.norm(A @ x - b) / np.linalg.norm(b)
        print(f"| {label} | {flops / 1e9:.1f} | {tf:.3f} | {ts:.4f} | {res:.1e} |")
    base = rows[0][1][1]
    print()
    for label, (_, tf, _, _) in rows[1:]:
        print(f"{label}: {base / tf:.2f}x faster per factorisation than PETSc's MUMPS")


if __name__ == "__main__":
    main()
