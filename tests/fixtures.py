"""Test fixtures: synthetic shards and datasets (numpy + data_spec only, so the trainer's
tests build datasets without the solver).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from data_spec.geometry import Geometry, box_mesh, write_geometry
from data_spec.shards import OgdenMaterial, Shard, SolverStats, geometry_path, write_shard


def synthetic_shard(geometry: Geometry, index: int, *, n_steps: int = 3, seed: int = 0,
                    scene_name: str = "synthetic", scene_hash: str = "0" * 64,
                    n_loads: int = 1) -> Shard:
    """A shard whose displacement is a smooth made-up field (not a solution of anything): a
    bump around each load node along its force, summed over the loads.
    """
    rng = np.random.default_rng([seed, index])
    fixed = geometry.regions.get("x0", np.arange(3))
    nodes, forces = [], []
    for _ in range(n_loads):
        nodes.append(int(rng.integers(geometry.n_nodes)))
        force = rng.normal(size=3)
        forces.append(force * 0.4 / np.linalg.norm(force))
    fr = np.arange(1, n_steps + 1) / n_steps
    x = geometry.points
    disp = 0.0
    for node, force in zip(nodes, forces):
        shape = (x[:, :1] - x[:, 0].min()) * np.exp(-np.sum((x - x[node]) ** 2, axis=1))[:, None]
        disp = disp + fr[:, None, None] * shape[None] * force[None, None, :] * 10.0
    return Shard(
        scene_name=scene_name, scene_hash=scene_hash, sim_index=index, seed=seed,
        geometry_id=geometry.geometry_id, load_kind="nodal", load_nodes=nodes,
        forces=np.array(forces), material=OgdenMaterial(c=[4.1e-3], m=[10.06], K=0.41),
        fixed_nodes=fixed, load_fractions=fr, output_nodes=np.arange(geometry.n_nodes),
        displacement=disp,
        stats=SolverStats(newton_iterations=np.full(n_steps, 3), residual_norms=np.full(
            n_steps, 1e-12), cutbacks=np.zeros(n_steps), wall_time=np.full(n_steps, 0.1),
            residual_history=[np.array([1.0, 1e-4, 1e-12])] * n_steps),
    )


TEST_SCENE = Path(__file__).parents[1] / "data_spec" / "scenes" / "tiny_scene1.toml"


def write_test_scene(directory: str | Path, scene_file: str | Path = TEST_SCENE,
                     n_simulations: int | None = None):
    """Copy a scene into a dataset directory as its ``scene.toml`` (with ``n_simulations``
    when given: how many the dataset holds); returns the Scene."""
    from data_spec.scene import load_scene

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    text = Path(scene_file).read_text()
    if n_simulations is not None:
        text = re.sub(r"(?m)^n_simulations = \d+", f"n_simulations = {n_simulations}", text)
    (directory / "scene.toml").write_text(text)
    return load_scene(directory / "scene.toml")


def synthetic_dataset(directory: str | Path, n_sims: int = 3, n: int = 3,
                      n_steps: int = 3, scene_file: str | Path = TEST_SCENE) -> Path:
    """Write a scene, a geometry and ``n_sims`` synthetic shards into ``directory`` (the
    shards carry the scene's name and hash and its number of loads, so the dataset validates).
    """
    directory = Path(directory)
    scene = write_test_scene(directory, scene_file, n_sims)  # the scene says how many
    geo = box_mesh(n)
    write_geometry(geometry_path(directory, geo.geometry_id), geo)
    for i in range(n_sims):
        write_shard(directory, synthetic_shard(geo, i, n_steps=n_steps, scene_name=scene.name,
                                               scene_hash=scene.hash,
                                               n_loads=scene["loads"]["count"]))
    return directory
