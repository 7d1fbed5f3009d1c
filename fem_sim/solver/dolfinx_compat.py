"""Every dolfinx-version-specific call of the project (dolfinx 0.5.2, Debian bookworm).

A move to dolfinx 0.9/0.10 changes this module only: mesh creation from arrays, function spaces,
quadrature spaces, form compilation, expression evaluation and PETSc assembly.
Calls marked "collective" must be made by every rank of the mesh's communicator.
"""

from __future__ import annotations

import basix
import numpy as np
import ufl
from dolfinx import fem, mesh
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

DOLFINX_API = "0.5"


def create_mesh(comm, points: np.ndarray | None, cells: np.ndarray | None):
    """Distribute a linear tetrahedral mesh given on the communicator's rank 0 (collective).

    Other ranks pass None. Returns the dolfinx mesh; ``input_node_ids(mesh)`` maps its local
    geometry nodes back to rows of ``points``.
    """
    if comm.rank == 0:
        x = np.ascontiguousarray(points, dtype=np.float64)
        c = np.ascontiguousarray(cells, dtype=np.int64)
    else:
        x = np.zeros((0, 3), dtype=np.float64)
        c = np.zeros((0, 4), dtype=np.int64)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", "tetrahedron", 1))
    return mesh.create_mesh(comm, c, x, domain)


def input_node_ids(msh) -> np.ndarray:
    """Source-mesh index of every local geometry node (owned and ghost)."""
    return np.asarray(msh.geometry.input_global_indices, dtype=np.int64)


def num_local_cells(msh) -> int:
    imap = msh.topology.index_map(msh.topology.dim)
    return imap.size_local + imap.num_ghosts


def vector_space(msh, degree: int):
    return fem.VectorFunctionSpace(msh, ("Lagrange", degree))


def scalar_space(msh, degree: int):
    return fem.FunctionSpace(msh, ("Lagrange", degree))


def constant(msh, value):
    return fem.Constant(msh, np.asarray(value, dtype=PETSc.ScalarType))


def interpolate(f, fn) -> None:
    """F <- fn(x) at f's interpolation points; fn takes (n, 3) coordinates."""
    f.interpolate(lambda x: fn(x.T))


def assemble_scalar(form, comm) -> float:
    """Assemble a functional and sum it over ranks (collective)."""
    return comm.allreduce(fem.assemble_scalar(form))


def vertex_dof_source_ids(msh, V) -> tuple[np.ndarray, np.ndarray]:
    """(local dof blocks, source node ids) for the vertex dofs of V (owned and ghost).

    The first four dofs of a cell in a Lagrange space are its vertex dofs, in the same local
    order as the cell's geometry nodes (P1 and P2 alike).
    """
    nc = num_local_cells(msh)
    geo = msh.geometry.dofmap.array.reshape(nc, -1)[:, :4].ravel()
    dofs = V.dofmap.list.array.reshape(nc, -1)[:, :4].ravel()
    src = input_node_ids(msh)[geo]
    blocks, first = np.unique(dofs, return_index=True)
    return blocks.astype(np.int32), src[first]


_TET_EDGES = ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))  # basix numbering, as tet.py


def edge_dof_source_ids(msh, V) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """P2 only: (local dof blocks, source id of end a, source id of end b) of the edge dofs.

    Cell dofs 4..9 of a P2 tetrahedron sit at the midpoints of edges 0..5 (basix numbering).
    """
    nc = num_local_cells(msh)
    geo = msh.geometry.dofmap.array.reshape(nc, -1)[:, :4]
    src = input_node_ids(msh)[geo]
    dofs = V.dofmap.list.array.reshape(nc, -1)
    if dofs.shape[1] != 10:
        raise ValueError(f"edge dofs need a P2 space, got {dofs.shape[1]} dofs per cell")
    blocks = dofs[:, 4:].ravel()
    ends = np.array(_TET_EDGES)
    a, b = src[:, ends[:, 0]].ravel(), src[:, ends[:, 1]].ravel()
    blocks, first = np.unique(blocks, return_index=True)
    return blocks.astype(np.int32), a[first], b[first]


def quadrature_points(degree: int) -> np.ndarray:
    """Reference points of FFCx's default tetrahedron rule of this degree."""
    return quadrature_rule(degree)[0]


def quadrature_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """(points (nq, 3), weights (nq,)) of FFCx's default tetrahedron rule of this degree, in
    the order of the quadrature spaces' dofs within a cell.
    """
    pts, wts = basix.make_quadrature(basix.CellType.tetrahedron, degree)
    return np.asarray(pts, dtype=np.float64), np.asarray(wts, dtype=np.float64)


def quadrature_function(msh, degree: int, shape: tuple[int, ...]):
    """A function with one value of ``shape`` per quadrature point (for stresses, tangents)."""
    if len(shape) == 1:
        el = ufl.VectorElement("Quadrature", msh.ufl_cell(), degree=degree, dim=shape[0],
                               quad_scheme="default")
    else:
        el = ufl.TensorElement("Quadrature", msh.ufl_cell(), degree=degree, shape=shape,
                               quad_scheme="default")
    return fem.Function(fem.FunctionSpace(msh, el))


def quadrature_cell_dofs(q_function, n_cells: int) -> np.ndarray:
    """(n_cells, n_points) dof blocks of a quadrature function, cell-major."""
    return q_function.function_space.dofmap.list.array.reshape(n_cells, -1)


def compile_form(expr, jit_options: dict | None = None):
    """Compile a UFL form (collective on the mesh's communicator)."""
    return fem.form(expr, jit_params=jit_options or {})


def compile_expression(expr, points: np.ndarray):
    return fem.Expression(expr, points)


def eval_expression(compiled, cells: np.ndarray) -> np.ndarray:
    return compiled.eval(cells)


def create_matrix(form):
    return fem_petsc.create_matrix(form)


def create_vector(form):
    return fem_petsc.create_vector(form)


def assemble_matrix(A, form) -> None:
    """Assemble into A (zeroed first), no boundary conditions (collective)."""
    A.zeroEntries()
    fem_petsc.assemble_matrix(A, form)
    A.assemble()


def assemble_vector(b, form) -> None:
    """Assemble into b, add ghost contributions to owners (collective)."""
    with b.localForm() as loc:
        loc.set(0.0)
    fem_petsc.assemble_vector(b, form)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)


def scatter_forward(u) -> None:
    """Update ghost values of a dolfinx Function from their owners (collective)."""
    u.x.scatter_forward()


def owned_size(V) -> int:
    """Number of owned dof blocks on this rank."""
    return V.dofmap.index_map.size_local


def global_block_indices(V, local_blocks: np.ndarray) -> np.ndarray:
    return V.dofmap.index_map.local_to_global(np.asarray(local_blocks, dtype=np.int32))


def evaluate_at_points(u, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values (n, value_size) of ``u`` at ``points`` (n, 3) on this process, and a mask of the
    points found in a local cell. Points in no local cell get the value of the closest local
    cell's polynomial (a short extrapolation across a boundary that another mesh of the same
    surface resolves differently); they are marked False in the mask.
    """
    from dolfinx import geometry

    msh = u.function_space.mesh
    tdim = msh.topology.dim
    x = np.ascontiguousarray(points, dtype=np.float64)
    tree = geometry.BoundingBoxTree(msh, tdim)
    colliding = geometry.compute_colliding_cells(msh, geometry.compute_collisions(tree, x), x)
    cells = np.full(x.shape[0], -1, dtype=np.int32)
    for i in range(x.shape[0]):
        found = colliding.links(i)
        if found.size:
            cells[i] = found[0]
    inside = cells >= 0
    if (~inside).any():
        n_local = num_local_cells(msh)
        mid = geometry.create_midpoint_tree(msh, tdim, np.arange(n_local, dtype=np.int32))
        cells[~inside] = geometry.compute_closest_entity(tree, mid, msh, x[~inside])
    return u.eval(x, cells), inside
