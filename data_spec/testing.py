"""Small exact objects for tests and examples: a structured box mesh and synthetic shards.

Numpy only, so the trainer's tests can build datasets without the solver.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from data_spec.geometry import Geometry, boundary_triangles, write_geometry
from data_spec.shards import OgdenMaterial, Shard, SolverStats, geometry_path, write_shard


def box_mesh(n: int = 4, size: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> Geometry:
    """A box [0, Lx] x [0, Ly] x [0, Lz] split into n^3 cubes of 6 tetrahedra each.

    Node (i, j, k) has id i + (n+1) j + (n+1)^2 k. The region ``x0`` holds the nodes on x = 0.
    """
    m = n + 1
    g = np.stack(np.meshgrid(*(np.linspace(0, s, m) for s in size), indexing="ij"), -1)
    points = g.transpose(2, 1, 0, 3).reshape(-1, 3)  # x fastest
    nid = np.arange(m ** 3).reshape(m, m, m)  # [k, j, i]
    cells = []
    # Kuhn split of each cube along its main diagonal: 6 tets, conforming across cubes.
    paths = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    for k in range(n):
        for j in range(n):
            for i in range(n):
                for path in paths:
                    c = [0, 0, 0]
                    tet = [nid[k, j, i]]
                    for axis in path:
                        c[axis] += 1
                        tet.append(nid[k + c[2], j + c[1], i + c[0]])
                    cells.append(tet)
    cells = np.array(cells, dtype=np.int64)
    e = points[cells[:, 1:]] - points[cells[:, :1]]
    negative = np.linalg.det(e) < 0
    cells[negative] = cells[negative][:, [0, 2, 1, 3]]  # positive orientation everywhere
    return Geometry(points=points, cells=cells,
                    surface_triangles=boundary_triangles(cells, points),
                    regions={"x0": np.flatnonzero(points[:, 0] == 0.0)},
                    description=f"box {size} mm, {n}^3 cubes of 6 tets")


def synthetic_shard(geometry: Geometry, index: int, *, n_steps: int = 3, seed: int = 0,
                    scene_name: str = "synthetic", scene_hash: str = "0" * 64) -> Shard:
    """A shard whose displacement is a smooth made-up field (not a solution of anything)."""
    rng = np.random.default_rng([seed, index])
    fixed = geometry.regions.get("x0", np.arange(3))
    node = int(rng.integers(geometry.n_nodes))
    force = rng.normal(size=3)
    force *= 0.4 / np.linalg.norm(force)
    fr = np.arange(1, n_steps + 1) / n_steps
    x = geometry.points
    shape = (x[:, :1] - x[:, 0].min()) * np.exp(-np.sum((x - x[node]) ** 2, axis=1))[:, None]
    disp = fr[:, None, None] * shape[None] * force[None, None, :] * 10.0
    return Shard(
        scene_name=scene_name, scene_hash=scene_hash, sim_index=index, seed=seed,
        geometry_id=geometry.geometry_id, load_kind="nodal", load_nodes=[node],
        forces=force[None], material=OgdenMaterial(c=[4.1e-3], m=[10.06], K=0.41),
        fixed_nodes=fixed, load_fractions=fr, output_nodes=np.arange(geometry.n_nodes),
        displacement=disp,
        stats=SolverStats(newton_iterations=np.full(n_steps, 3), residual_norms=np.full(
            n_steps, 1e-12), cutbacks=np.zeros(n_steps), wall_time=np.full(n_steps, 0.1),
            residual_history=[np.array([1.0, 1e-4, 1e-12])] * n_steps),
    )


TEST_SCENE = Path(__file__).with_name("scenes") / "tiny_scene1.toml"


def write_test_scene(directory: str | Path, scene_file: str | Path = TEST_SCENE):
    """Copy a scene into a dataset directory as its ``scene.toml``; returns the Scene."""
    from data_spec.scene import load_scene

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "scene.toml").write_text(Path(scene_file).read_text())
    return load_scene(directory / "scene.toml")


def synthetic_dataset(directory: str | Path, n_sims: int = 3, n: int = 3,
                      n_steps: int = 3, scene_file: str | Path = TEST_SCENE) -> Path:
    """Write a scene, a geometry and ``n_sims`` synthetic shards into ``directory`` (the
    shards carry the scene's name and hash, so the dataset validates).
    """
    directory = Path(directory)
    scene = write_test_scene(directory, scene_file)
    geo = box_mesh(n)
    write_geometry(geometry_path(directory, geo.geometry_id), geo)
    for i in range(n_sims):
        write_shard(directory, synthetic_shard(geo, i, n_steps=n_steps, scene_name=scene.name,
                                               scene_hash=scene.hash))
    return directory
