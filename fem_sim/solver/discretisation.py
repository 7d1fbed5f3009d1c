"""The discretisation of one problem: the distributed mesh, the displacement space, the
quadrature-space coefficients that carry stress and tangent, the compiled forms, and the maps
between source-mesh nodes and local dofs (constraints, nodal loads, gathering results).

Design: the material is evaluated at quadrature points outside UFL (:mod:`fem_sim.material`,
exact at coinciding stretches) and enters the compiled forms as quadrature-space coefficients,
so the forms are compiled once per problem and one problem serves every material and load.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from mpi4py import MPI

from fem_sim.solver import dolfinx_compat as dc
from fem_sim.solver.loads import Constraint, NodalLoad, PatchLoad


def _flat(T):
    return ufl.as_vector([T[i, j] for i in range(3) for j in range(3)])


@dataclass
class DofConstraints:
    """Constrained dofs of the local process and their prescribed values at load fraction 1."""

    local: np.ndarray          # local dof indices (owned and ghost)
    owned: np.ndarray          # the owned ones
    values_owned: np.ndarray   # their prescribed values (mm)
    global_: np.ndarray        # the owned ones as global indices (PETSc's zeroRowsColumns)
    value_norm: float          # max |prescribed value| over all ranks (0: fixed nodes only)


class Discretisation:
    """Mesh, space, coefficients, forms and dof maps (construction is collective on ``comm``).

    ``points``/``cells`` are given on rank 0 (None elsewhere); results come back in their
    node order whatever the partition.
    """

    def __init__(self, comm, points: np.ndarray | None, cells: np.ndarray | None,
                 degree: int, quadrature_degree: int):
        self.comm, self.degree, self.qdeg = comm, degree, quadrature_degree
        self.n_nodes = comm.bcast(points.shape[0] if comm.rank == 0 else None, root=0)
        self.mesh = dc.create_mesh(comm, points, cells)
        self.V = dc.vector_space(self.mesh, degree)
        self.u = dc.fem.Function(self.V)
        self.n_cells = dc.num_local_cells(self.mesh)
        self.cells = np.arange(self.n_cells, dtype=np.int32)
        qd = quadrature_degree
        self.P_q = dc.quadrature_function(self.mesh, qd, (9,))
        self.A_q = dc.quadrature_function(self.mesh, qd, (9, 9))
        self.W_q = dc.quadrature_function(self.mesh, qd, (1,))
        self.q_dofs = dc.quadrature_cell_dofs(self.P_q, self.n_cells).ravel()
        # Quadrature dofs numbered cell by cell (the usual case): the kernel writes straight
        # into the coefficient arrays.
        self.q_contiguous = np.array_equal(self.q_dofs, np.arange(self.q_dofs.size))
        v, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        dx = ufl.dx(metadata={"quadrature_degree": qd})
        self.L = dc.compile_form(ufl.inner(self.P_q, _flat(ufl.grad(v))) * dx)
        self.energy_form = dc.compile_form(self.W_q[0] * dx)
        self.a = dc.compile_form(
            ufl.inner(ufl.dot(self.A_q, _flat(ufl.grad(du))), _flat(ufl.grad(v))) * dx)
        self.grad_u = dc.compile_expression(ufl.grad(self.u), dc.quadrature_points(qd))
        # Patch loads: traction t w(x) on the boundary, w a finite-element footprint function.
        self.w = dc.fem.Function(dc.scalar_space(self.mesh, degree))
        self.t = dc.constant(self.mesh, np.zeros(3))
        ds = ufl.ds(metadata={"quadrature_degree": 2 * degree})
        self.L_patch = dc.compile_form(ufl.inner(self.t * self.w, v) * ds)
        self.patch_area = dc.compile_form(self.w * ds)
        self.n_owned = dc.owned_size(self.V)
        blocks, src = dc.vertex_dof_source_ids(self.mesh, self.V)
        owned = blocks < self.n_owned
        self.owned_vertex_blocks, self.owned_vertex_src = blocks[owned], src[owned]
        self.src_to_block = dict(zip(src.tolist(), blocks.tolist()))

    def new_vector(self):
        """A PETSc vector laid out like the residual (collective)."""
        return dc.create_vector(self.L)

    def point_values(self, q, size: int) -> np.ndarray:
        """Values of a quadrature function at the local cells' points, cell-major:
        (ncells * points per cell, size).
        """
        arr = q.x.array.reshape(-1, size)
        return arr[: self.q_dofs.size] if self.q_contiguous else arr[self.q_dofs]

    # ------------------------------------------------------------------------------------------
    # Source nodes -> dofs
    # ------------------------------------------------------------------------------------------
    def constraints(self, constraints: list[Constraint]) -> DofConstraints:
        """Map node constraints to local dofs (collective). For P2, an edge dof is constrained
        (to the mean of its ends' values: the P1 interpolant) when both ends are, in that
        component.
        """
        local, values = [], []
        by_node: dict[tuple[int, int], float] = {}
        for c in constraints:
            nodes = np.atleast_1d(np.asarray(c.nodes, dtype=np.int64))
            if nodes.size and (nodes.min() < 0 or nodes.max() >= self.n_nodes):
                raise ValueError(f"Constraint: node ids outside [0, {self.n_nodes})")
            vals = np.broadcast_to(np.asarray(c.values, dtype=np.float64),
                                   (nodes.size, len(c.components)))
            for n, row in zip(nodes.tolist(), vals):
                for comp, val in zip(c.components, row):
                    by_node[(n, comp)] = float(val)
        for (n, comp), val in by_node.items():
            blk = self.src_to_block.get(n)
            if blk is not None:
                local.append(3 * blk + comp)
                values.append(val)
        if self.degree == 2:
            for blk, a, b in zip(*[x.tolist() for x in dc.edge_dof_source_ids(self.mesh, self.V)]):
                for comp in range(3):
                    va, vb = by_node.get((a, comp)), by_node.get((b, comp))
                    if va is not None and vb is not None:
                        local.append(3 * blk + comp)
                        values.append(0.5 * (va + vb))
        local = np.asarray(local, dtype=np.int32)
        values = np.asarray(values, dtype=np.float64)
        local, first = np.unique(local, return_index=True)
        values = values[first]
        owned = local < 3 * self.n_owned
        value_norm = self.comm.allreduce(float(np.abs(values).max()) if values.size else 0.0,
                                         op=MPI.MAX)
        fixed_owned = local[owned]
        blocks = dc.global_block_indices(self.V, fixed_owned // 3)
        n_fixed = self.comm.allreduce(int(owned.sum()), op=MPI.SUM)
        if n_fixed == 0:
            raise ValueError("OgdenProblem.solve: no constrained degree of freedom (the body "
                             "could move rigidly); give at least one Constraint")
        return DofConstraints(local=local, owned=fixed_owned, values_owned=values[owned],
                              global_=(3 * blocks + fixed_owned % 3).astype(np.int32),
                              value_norm=value_norm)

    def load_vector(self, loads: list, f_ext) -> float:
        """f_ext at load fraction 1 from nodal and patch loads; returns |f_ext| (collective)."""
        with f_ext.localForm() as loc:
            loc.set(0.0)
        for ld in loads:
            if isinstance(ld, PatchLoad):
                dc.interpolate(self.w, ld.weight)
                area = dc.assemble_scalar(self.patch_area, self.comm)
                if not area > 0:
                    raise ValueError(f"PatchLoad at {ld.centre} (radius {ld.radius} mm) covers "
                                     "no boundary")
                self.t.value[:] = ld.force / area
                tmp = f_ext.duplicate()
                dc.assemble_vector(tmp, self.L_patch)
                f_ext.axpy(1.0, tmp)
                tmp.destroy()
        arr = f_ext.array
        for ld in loads:
            if not isinstance(ld, NodalLoad):
                continue
            bad = (ld.nodes < 0) | (ld.nodes >= self.n_nodes)
            if bad.any():
                raise ValueError(f"NodalLoad: node ids {ld.nodes[bad][:5].tolist()} outside "
                                 f"[0, {self.n_nodes})")
            for n, f in zip(ld.nodes.tolist(), ld.forces):
                blk = self.src_to_block.get(n)
                if blk is not None and blk < self.n_owned:
                    arr[3 * blk: 3 * blk + 3] += f
        return f_ext.norm()

    def node_blocks(self, nodes) -> np.ndarray:
        """Owned dof blocks of a node set: its vertex dofs, and for P2 the edge dofs whose two
        ends are in the set.
        """
        members = set(np.asarray(nodes, dtype=np.int64).tolist())
        blocks = [b for b, n in zip(self.owned_vertex_blocks.tolist(),
                                    self.owned_vertex_src.tolist()) if n in members]
        if self.degree == 2:
            eb, ea, ee = dc.edge_dof_source_ids(self.mesh, self.V)
            blocks += [b for b, x, y in zip(eb.tolist(), ea.tolist(), ee.tolist())
                       if b < self.n_owned and x in members and y in members]
        return np.asarray(blocks, dtype=np.int64)

    # ------------------------------------------------------------------------------------------
    # Dofs -> source nodes
    # ------------------------------------------------------------------------------------------
    def gather_vertex_values(self, arr_blocked: np.ndarray) -> np.ndarray | None:
        """Values (n_local_blocks, 3) at owned vertex dofs -> (n_nodes, 3) on rank 0
        (collective).
        """
        vals = arr_blocked[self.owned_vertex_blocks]
        parts = self.comm.gather((self.owned_vertex_src, vals), root=0)
        if self.comm.rank != 0:
            return None
        out = np.full((self.n_nodes, 3), np.nan)
        for src, v in parts:
            out[src] = v
        return out
