"""A grasp: a patch of nodes moved rigidly by a prescribed displacement, and the force back
(the reaction at every stored load step, ``OgdenProblem.solve(..., reactions=...)``)."""

import numpy as np
import pytest

from fem_sim import Constraint, OgdenMaterial, OgdenProblem
from tests.fixtures import box_mesh

C1, M1 = 4.1e-3, 10.06


def simple_shear_stress(gamma: float) -> float:
    """sigma_xz of the uncoupled Ogden solid in simple shear x += gamma z, by hand: J = 1, so
    only the deviatoric part acts; B = [[1 + g^2, g], [g, 1]] in (x, z) has eigenvalues l^2 and
    l^-2 with l = g/2 + sqrt(1 + g^2/4), and B_xz = (l^2 - l^-2) n1x n1z = g, so
    sigma_xz = (sigma_1 - sigma_2) n1x n1z = (c/m)(l^m - l^-m) g / (l^2 - l^-2). Small g:
    c g / 2 = mu g."""
    lam = gamma / 2 + np.sqrt(1 + gamma**2 / 4)
    return (C1 / M1) * (lam**M1 - lam**-M1) * gamma / (lam**2 - lam**-2)


@pytest.mark.parametrize("degree", [1, 2], ids=["P1", "P2"])
def test_a_grasped_face_in_finite_simple_shear_gives_the_closed_form_force_at_every_step(degree):
    """A 2 x 1 x 1 mm block: the bottom face fixed, the top face grasped and moved 0.6 mm
    along x (shear 0.6), the sides moved as simple shear so the state is homogeneous and
    exact for P1 and P2. The tool's force at each stored step is sigma_xz(gamma) times the
    top area, along x; nothing along y (along z the normal stress of simple shear, which
    depends on the pressure the held sides set: not asserted)."""
    from mpi4py import MPI

    g = box_mesh(2, (2.0, 1.0, 1.0))
    x = g.points
    top, bottom = np.flatnonzero(x[:, 2] == 1.0), np.flatnonzero(x[:, 2] == 0.0)
    sides = np.setdiff1d(np.arange(len(x)), np.concatenate([top, bottom]))
    sides = sides[np.isin(sides, g.surface_nodes)]
    d = np.array([0.6, 0.0, 0.0])
    shear = np.zeros((sides.size, 3))
    shear[:, 0] = 0.6 * x[sides, 2]
    prob = OgdenProblem(MPI.COMM_WORLD, x, g.cells, degree=degree,
                        settings={"rtol": 1e-11, "atol": 1e-14})
    mat = OgdenMaterial((C1,), (M1,), 200 * C1 / 2)
    fractions = [0.25, 0.5, 1.0]
    sol = prob.solve(mat, [Constraint(bottom), Constraint(top, values=d),
                           Constraint(sides, values=shear)], [], fractions, reactions=[top])
    assert sol.status == "ok", sol.failure_reason
    assert sol.reaction.shape == (3, 1, 3)
    want = [simple_shear_stress(0.6 * f) * 2.0 for f in fractions]   # top area 2 mm^2
    np.testing.assert_allclose(sol.reaction[:, 0, 0], want, rtol=1e-7)
    np.testing.assert_allclose(sol.reaction[:, 0, 1], 0.0, atol=1e-9 * max(want))
    # the stored displacement is the homogeneous shear itself
    np.testing.assert_allclose(sol.displacement[-1][:, 0], 0.6 * x[:, 2], atol=1e-9)
    # small shear: mu g A, the small-strain shear modulus (mu = c/2)
    assert simple_shear_stress(1e-4) / 1e-4 == pytest.approx(C1 / 2, rel=1e-7)


def test_a_grasp_on_a_liver_balances_the_fixed_region_and_moves_rigidly():
    """The phantom at 16 mm: a 10 mm patch far from the vena cava grasped and pulled 20 mm:
    the tool's force and the fixed region's reaction sum to zero at every step (no other
    load), the patch moves by the step's share of the pull, and the force grows with it."""
    from mpi4py import MPI

    from fem_sim.geometry.phantom import make_phantom

    g = make_phantom(0, 16.0)
    fixed = g.regions["vena_cava"]
    surf = np.setdiff1d(g.surface_nodes, fixed)
    far = surf[np.argmax(np.linalg.norm(g.points[surf][:, None] - g.points[fixed][None],
                                        axis=2).min(axis=1))]
    patch = surf[np.linalg.norm(g.points[surf] - g.points[far], axis=1) <= 10.0]
    d = 20.0 * np.array([0.0, 0.0, 1.0])
    prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=1)
    mat = OgdenMaterial((C1,), (M1,), 200 * C1 / 2)
    sol = prob.solve(mat, [Constraint(fixed), Constraint(patch, values=d)], [],
                     [0.5, 1.0], reactions=[patch, fixed])
    assert sol.status == "ok", sol.failure_reason
    r = sol.reaction
    scale = np.abs(r).max()
    np.testing.assert_allclose(r[:, 0] + r[:, 1], 0.0, atol=1e-6 * scale)
    np.testing.assert_allclose(sol.displacement[-1][patch], np.broadcast_to(d, (patch.size, 3)),
                               atol=1e-9)
    assert r[1, 0, 2] > r[0, 0, 2] > 0.0   # pulled up: the tool pulls up, harder further


@pytest.mark.mpi
def test_a_grasp_scene_end_to_end_records_each_tools_displacement_and_force(tmp_path):
    """fem_sim generate on a tiny grasp scene (two tools of 10 mm pulled 5-15 mm away from
    the vena cava, on two ranks): every shard is valid and holds, at each stored step, each
    tool's displacement (the load fraction times its pull, which its patch's nodes follow)
    and a finite force that does positive work; the force grows with the pull. The small-
    strain responses of the dataset hold each patch at its pull (order 2 refused)."""
    import subprocess
    import sys
    from pathlib import Path

    from data_spec import list_shards, load_scene, read_shard, validate_dataset
    from fem_sim.batch import cases as cs
    from fem_sim.batch.chunked import mpirun_env

    root = Path(__file__).parents[2]
    text = (root / "data_spec" / "scenes" / "tiny_scene1.toml").read_text()
    text = text.replace('name = "tiny_scene1"', 'name = "tiny_grasp"')
    text = text.replace('kind = "nodal"', 'kind = "grasp"\npatch_radius = 10.0')
    text = text.replace("count = 1", "count = 2\nmin_separation = 25.0")
    text = text.replace("magnitude = 0.4         # N", "magnitude = [5.0, 15.0]   # mm")
    text = text.replace('direction = "uniform"', 'direction = "away"')
    text = text.replace("mesh_size = 20.0", "mesh_size = 14.0")
    scene_file = tmp_path / "grasp.toml"
    scene_file.write_text(text)
    out = tmp_path / "d"
    res = subprocess.run(["mpirun", "-n", "2", sys.executable, "-m", "fem_sim", "generate",
                          str(scene_file), "--out", str(out), "--no-progress"],
                         env=mpirun_env(PYTHONPATH=str(root)), capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr
    assert validate_dataset(out) == []
    scene = load_scene(scene_file)
    shards = [read_shard(p) for p in list_shards(out)]
    assert len(shards) == 4 and all(s.status == "ok" for s in shards), \
        [s.failure_reason for s in shards]
    from data_spec import read_geometry
    from data_spec.shards import geometry_path

    for s in shards:
        g = read_geometry(geometry_path(out, s.geometry_id))
        case = cs.make_case(scene, s.sim_index, g, s.fixed_nodes)
        lam = np.asarray(s.load_fractions)
        assert s.load_kind == "grasp" and s.reaction.shape == (3, 2, 3)
        np.testing.assert_allclose(s.tool_displacement, lam[:, None, None] * case.displacements)
        assert np.all(np.linalg.norm(case.displacements, axis=1) >= 5.0)
        for tool, patch in enumerate(cs.grasp_patches(case, g, s.fixed_nodes)):
            np.testing.assert_allclose(
                s.displacement[:, patch], np.broadcast_to(
                    s.tool_displacement[:, tool, None], (3, patch.size, 3)), atol=1e-9)
            # away from the vena cava: the pull's direction leaves the nearest fixed node
            near = g.points[s.fixed_nodes][np.argmin(np.linalg.norm(
                g.points[s.fixed_nodes] - g.points[case.load_nodes[tool]], axis=1))]
            assert np.dot(case.displacements[tool], g.points[case.load_nodes[tool]] - near) > 0
        work = np.einsum("std,td->s", s.reaction, case.displacements)
        assert np.all(np.isfinite(s.reaction)) and np.all(work > 0)
        assert np.all(np.diff(work) > 0)
    lf = _small_strain_responses(out, root, scene, g, shards)
    _one_liver_responses(out, root, scene_file, shards, lf)


def _one_liver_responses(out, root, scene_file, shards, lf) -> None:
    """fem_sim linear on the one-liver grasp scene itself (make patient LOAD=grasp's step:
    the free surface's Green's function, each case's grasp over it) gives every simulation
    the population path's field and tools' forces; another order or drawn cases refused."""
    import subprocess
    import sys

    from data_spec.linear_fields import read_dataset_linear
    from fem_sim.batch.chunked import mpirun_env

    lin = [sys.executable, "-m", "fem_sim", "linear", str(scene_file), "--out", str(out),
           "--green", "--order"]
    env = mpirun_env(PYTHONPATH=str(root))
    for bad in (["2"], ["1", "--synthetic", "3"]):
        res = subprocess.run(lin + bad, env=env, capture_output=True, text=True, timeout=600)
        assert res.returncode != 0 and "--green with --order 1, no --synthetic" in res.stderr
    res = subprocess.run(lin + ["1"], env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    one = read_dataset_linear(out)
    assert one.green is not None and one.green_nodes.size > 0
    for s in shards:
        a, b = one.rows([s.sim_index])[0], lf.rows([s.sim_index])[0]
        scale = np.abs(lf.displacement[b]).max()
        np.testing.assert_allclose(one.displacement[a], lf.displacement[b], atol=1e-6 * scale)
        np.testing.assert_allclose(one.tool_force[a], lf.tool_force[b], rtol=1e-6)


def _small_strain_responses(out, root, scene, g, shards):
    """The grasp dataset's small-strain responses checked against its shards."""
    import subprocess
    import sys

    # each simulation's small-strain response (fem_sim linear --population, order 1: the
    # Green's function rows of its patches, G_PP f = d) holds every patch at its tool's pull
    from data_spec.linear_fields import read_dataset_linear
    from fem_sim.batch import cases as cs
    from fem_sim.batch.chunked import mpirun_env

    lin = ["-m", "fem_sim", "linear", "--population", str(out), "--order"]
    res = subprocess.run([sys.executable, *lin, "2"], env=mpirun_env(PYTHONPATH=str(root)),
                         capture_output=True, text=True, timeout=600)
    assert res.returncode != 0 and "a grasp's second-order term is not built" in res.stderr
    res = subprocess.run([sys.executable, *lin, "1"], env=mpirun_env(PYTHONPATH=str(root)),
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    lf = read_dataset_linear(out, shards[0].geometry_id)
    for s in shards:
        case = cs.make_case(scene, s.sim_index, g, s.fixed_nodes)
        u1 = lf.displacement[lf.rows([s.sim_index])[0]]
        for patch, pull in zip(cs.grasp_patches(case, g, s.fixed_nodes), case.displacements):
            np.testing.assert_allclose(u1[patch], np.broadcast_to(pull, (patch.size, 3)),
                                       atol=1e-4 * np.linalg.norm(pull))
        # and its tools' small-strain forces: positive work along the pull, near the FE
        # reaction at the first load step (a few mm: within 10 %), and the Ogden liver
        # stiffening beyond them as the pull grows (the FE force over the linear one rises)
        f1 = lf.tool_force[lf.rows([s.sim_index])[0]]
        assert np.all(np.einsum("td,td->t", f1, case.displacements) > 0)
        ratio = (np.linalg.norm(s.reaction, axis=2)
                 / np.linalg.norm(s.load_fractions[:, None, None] * f1, axis=2))
        assert np.all(np.abs(ratio[0] - 1.0) < 0.1) and np.all(ratio[-1] > ratio[0])
    return lf



def test_a_grasp_scene_is_checked_and_a_patch_on_the_fixed_region_is_a_recorded_failure(
        tmp_path):
    """The scene: a grasp's patch radius defaults to 10 mm, three tools and explicit cases are
    refused with the key; a tool whose patch reaches the fixed region (or another tool's) is
    a CaseError naming the key to raise, which generate records as the shard's reason."""
    from pathlib import Path

    from data_spec import load_scene
    from data_spec.scene import SceneError
    from fem_sim.batch import cases as cs
    from fem_sim.geometry.phantom import make_phantom

    tiny = (Path(__file__).parents[2] / "data_spec" / "scenes" / "tiny_scene1.toml").read_text()
    grasp = tiny.replace('kind = "nodal"', 'kind = "grasp"').replace(
        "min_distance_to_fixed = 20.0", "min_distance_to_fixed = 0.0")
    f = tmp_path / "g.toml"
    f.write_text(grasp)
    scene = load_scene(f)
    assert scene["loads"]["patch_radius"] == 10.0
    f.write_text(grasp.replace("count = 1", "count = 3"))
    with pytest.raises(SceneError, match="loads.count: 3 tools; a grasp has 1 to 2"):
        load_scene(f)
    f.write_text(grasp + "\n[[cases]]\nload_nodes = [3]\nforces = [[0, 0, 1]]\n")
    with pytest.raises(SceneError, match="a grasp scene draws its tools"):
        load_scene(f)
    g = make_phantom(0, 20.0)
    fixed = g.regions["vena_cava"]
    near = fixed[0]   # a tool on the fixed region itself
    case = cs.Case(0, 0, "grasp", np.array([near]), np.zeros((1, 3)),
                   cs.base_material(scene), 10.0, displacements=np.array([[0.0, 0.0, 5.0]]))
    with pytest.raises(cs.CaseError, match="reaches the fixed region: raise "
                                           "loads.min_distance_to_fixed"):
        cs.grasp_patches(case, g, fixed)


def _far_patch(g, fixed, radius=10.0):
    """The surface node farthest from the fixed region and its grasp patch (the solver's rule)."""
    from data_spec.eligible_loads import grasp_patch

    surf = np.setdiff1d(g.surface_nodes, fixed)
    far = surf[np.argmax(np.linalg.norm(g.points[surf][:, None] - g.points[fixed][None],
                                        axis=2).min(axis=1))]
    return far, grasp_patch(g.points, g.surface_nodes, far, radius)


def test_the_green_grasp_is_the_solvers_grasp_in_the_small_strain_limit():
    """data_spec.green_grasp on the phantom's own Green's function (a unit response at every free
    surface node, as fem_sim linear --green makes it) against the Ogden solve of the same
    grasp: the Green's function is symmetric among the patch nodes (Maxwell-Betti); its grasp
    puts every patch node at the tool's displacement; field and force agree with the FE to
    a relative error that falls as the pull (the geometric and material nonlinearity, first
    order in the pull: 10x less for a 10x smaller pull), below 1e-3 at a 0.01 mm pull."""
    from mpi4py import MPI

    from data_spec.green_grasp import GreenGrasp
    from fem_sim.geometry.phantom import make_phantom

    g = make_phantom(0, 16.0)
    fixed = g.regions["vena_cava"]
    gnodes = np.setdiff1d(g.surface_nodes, fixed)
    _, patch = _far_patch(g, fixed)
    mat = OgdenMaterial((C1,), (M1,), 200 * C1 / 2)
    prob = OgdenProblem(MPI.COMM_SELF, g.points, g.cells, degree=1, settings={"rtol": 1e-10})
    green = prob.unit_responses(mat, [Constraint(fixed)], gnodes, rtol=1e-12)
    rows = np.searchsorted(gnodes, patch)
    gpp = green[rows][:, :, patch].reshape(3 * patch.size, 3 * patch.size)
    np.testing.assert_allclose(gpp, gpp.T, atol=1e-8 * np.abs(gpp).max())
    grasp = GreenGrasp(green, gnodes, np.arange(g.n_nodes), [patch])
    direction = np.array([0.3, -0.4, 0.866]) / np.linalg.norm([0.3, -0.4, 0.866])
    errors = []
    for pull in (0.1, 0.01):
        d = pull * direction[None]
        u, force = grasp(d)
        np.testing.assert_allclose(u[patch], np.broadcast_to(d, (patch.size, 3)),
                                   atol=1e-9 * pull)
        sol = prob.solve(mat, [Constraint(fixed), Constraint(patch, values=d[0])], [], [1.0],
                         reactions=[patch])
        assert sol.status == "ok", sol.failure_reason
        fe_u, fe_f = sol.displacement[-1], sol.reaction[-1]
        errors.append((np.abs(fe_u - u).max() / np.abs(fe_u).max(),
                       np.linalg.norm(fe_f - force) / np.linalg.norm(fe_f)))
    (u_big, f_big), (u_small, f_small) = errors
    assert u_small < 1e-3 and f_small < 1e-3, errors
    assert 5.0 < u_big / u_small < 20.0 and 5.0 < f_big / f_small < 20.0, errors
