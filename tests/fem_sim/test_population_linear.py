"""fem_sim linear --population: each liver of a population dataset linearised at u = 0 under
its own simulations' loads, one file per liver, against the nonlinear solve at a small load
on that liver; resumable; a directory that is no dataset named."""

import numpy as np
import pytest

from data_spec.geometry import box_mesh, write_geometry
from data_spec.linear_fields import linear_fields_path, read_linear_fields
from data_spec.shards import geometry_path, write_shard
from tests.fixtures import synthetic_shard, write_test_scene


def _two_livers(d):
    """Two box livers (2^3 and 3^3 cells, the second 1.5 times larger), three simulations
    (0 and 2 on the first), each fixed on its face x = 0 (synthetic fields: only their loads,
    fixed nodes and material are read)."""
    scene = write_test_scene(d, n_simulations=3)
    livers = [box_mesh(2), box_mesh(3, (1.5, 1.5, 1.5))]
    for g in livers:
        g.regions["x0"] = np.flatnonzero(g.points[:, 0] == 0.0)
        write_geometry(geometry_path(d, g.geometry_id), g)
    for i, g in enumerate([livers[0], livers[1], livers[0]]):
        write_shard(d, synthetic_shard(g, i, scene_name=scene.name, scene_hash=scene.hash))
    return livers


def test_each_liver_is_linearised_under_its_own_loads(tmp_path):
    """u1 of every simulation equals the nonlinear solve at load fraction 1e-7 divided by it
    (the tangent at rest, whose error is O(1e-5) relative here) on that simulation's own liver,
    fixed nodes and force; a second run writes nothing, one more simulation redoes its
    liver only."""
    from mpi4py import MPI

    from data_spec import load_scene
    from data_spec.shards import list_shards, read_shard
    from fem_sim import Constraint, NodalLoad, OgdenProblem
    from fem_sim.batch.linear import population_linear_fields

    livers = _two_livers(tmp_path)
    solver = load_scene(tmp_path / "scene.toml")["solver"]   # the dataset's discretisation
    written = population_linear_fields(tmp_path, order=2, progress=False)
    assert sorted(p.name for p in written) == sorted(f"{g.geometry_id}.h5" for g in livers)
    for sh in map(read_shard, list_shards(tmp_path)):
        g = livers[0] if sh.geometry_id == livers[0].geometry_id else livers[1]
        lf = read_linear_fields(linear_fields_path(tmp_path, g.geometry_id))
        assert lf.order == 2 and sorted(lf.case_index) == ([0, 2] if g is livers[0] else [1])
        row = list(lf.case_index).index(sh.sim_index)
        prob = OgdenProblem(MPI.COMM_SELF, g.points, g.cells, degree=solver["degree"],
                            quadrature_degree=solver["quadrature_degree"],
                            settings={"rtol": 1e-12, "atol": 1e-16})
        lam = 1e-7   # 0.4 N on a 1 mm box of mu = 2 kPa: strains of 1e-5 at this fraction
        sol = prob.solve(sh.material, [Constraint(sh.fixed_nodes)],
                         [NodalLoad(sh.load_nodes, sh.forces)], np.array([lam]))
        small = sol.displacement[0] / lam
        np.testing.assert_allclose(lf.displacement[row], small, atol=1e-4 * np.abs(small).max())
        assert np.abs(lf.second_order[row]).max() > 0
    assert population_linear_fields(tmp_path, order=2, progress=False) == []
    # a file of order 2 holds the first-order responses: order 1 redoes nothing
    assert population_linear_fields(tmp_path, order=1, progress=False) == []
    from data_spec.grown import record_size

    record_size(tmp_path, 3)   # the dataset grows as generate grows it: its earlier size kept
    scene = write_test_scene(tmp_path, n_simulations=4)
    write_shard(tmp_path, synthetic_shard(livers[1], 3, scene_name=scene.name,
                                          scene_hash=scene.hash))
    again = population_linear_fields(tmp_path, order=2, progress=False)
    assert [p.name for p in again] == [f"{livers[1].geometry_id}.h5"]


def test_a_directory_without_a_scene_is_named(tmp_path):
    from fem_sim.batch.linear import population_linear_fields

    with pytest.raises(ValueError, match=f"{tmp_path}: no scene.toml"):
        population_linear_fields(tmp_path, progress=False)


def test_the_command_takes_one_form_or_says_which(tmp_path):
    """fem_sim linear with neither SCENE --out nor --population, or with both: exit 2 and a
    line naming the two forms; --population refuses the one-liver options."""
    import subprocess
    import sys

    def run(*args):
        return subprocess.run([sys.executable, "-m", "fem_sim", "linear", *args],
                              capture_output=True, text=True)

    for args in ((), ("scene.toml", "--out", "d", "--population", "d")):
        r = run(*args)
        assert r.returncode == 2 and "give SCENE --out DIR, or --population DATA" in r.stderr
    _two_livers(tmp_path)
    r = run("--population", str(tmp_path), "--green")
    assert r.returncode == 2 and "--population takes the simulations' loads only" in r.stderr
