"""surrogate.grasp and data_spec.green_grasp without a liver: a pressed patch's shares, and a
grasp over a Green's function known in closed form; a model of grasps trained, answering a
grasp with its rest and its force."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from data_spec.geometry import box_mesh
from data_spec.green_grasp import GreenGrasp
from surrogate.grasp import patch_weights


def test_a_pressed_patch_spreads_the_whole_force_by_area_and_bump():
    """On the top face of a block (a regular grid), the shares sum to one, fall with the
    distance to the centre, vanish at the radius, and nodes at the same distance with the
    same lumped area carry the same share."""
    g = box_mesh(8, (8.0, 8.0, 1.0))
    top = g.surface_nodes[g.points[g.surface_nodes, 2] == 1.0]
    centre = top[np.argmin(np.linalg.norm(g.points[top, :2] - 4.0, axis=1))]
    patch = top[np.linalg.norm(g.points[top] - g.points[centre], axis=1) <= 2.0]
    w = patch_weights(g.points, g.surface_triangles, patch, centre, 2.0)
    r = np.linalg.norm(g.points[patch] - g.points[centre], axis=1)
    assert w.sum() == pytest.approx(1.0) and np.all(w >= 0)
    assert w[r == 0].item() == w.max() and np.all(w[r == 2.0] == 0)
    ring = np.isclose(r, 1.0)
    assert ring.sum() == 4 and np.allclose(w[ring], w[ring][0])   # the four at 1 mm
    with pytest.raises(ValueError, match="carries no area"):
        patch_weights(g.points, g.surface_triangles, patch[r == 2.0][:1], centre, 2.0)


def test_a_grasp_of_independent_springs_is_their_stiffness_and_a_bad_patch_is_named():
    """A Green's function of uncoupled nodes, u_i = f_i / k_i (a diagonal, closed form): a
    tool holding nodes of stiffness k_i feels sum k_i d, moves only its own nodes, and two
    tools do not feel each other; a node without a row, a wrong displacement shape or NaN
    is refused."""
    k = np.array([1.0, 2.0, 4.0, 8.0])
    green = np.zeros((4, 3, 4, 3))
    for i in range(4):
        green[i, :, i, :] = np.eye(3) / k[i]
    nodes = np.array([10, 11, 12, 13])      # mesh ids of the rows and columns
    grasp = GreenGrasp(green, nodes, nodes, [[10, 11], [13]])
    d = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -2.0]])
    u, force = grasp(d)
    np.testing.assert_allclose(force, [[3.0, 0.0, 0.0], [0.0, 0.0, -16.0]])
    np.testing.assert_allclose(u, [[1, 0, 0], [1, 0, 0], [0, 0, 0], [0, 0, -2]], atol=1e-12)
    np.testing.assert_allclose(grasp.stiffness, np.diag([3, 3, 3, 8, 8, 8.0]))
    with pytest.raises(ValueError, match="grasped node 9 has no unit response"):
        GreenGrasp(green, nodes, nodes, [[9, 10]])
    with pytest.raises(ValueError, match=r"expected finite \(2, 3\) mm"):
        grasp(d[:1])
    with pytest.raises(ValueError, match="expected finite"):
        grasp.force(np.full((2, 3), np.nan))


@pytest.mark.dataset
def test_a_model_of_grasps_adds_its_rest_off_the_patch_and_stiffens_the_force():
    """surrogate.grasp.grasp_over_base with a stand-in placed network whose rest is known:
    the rest is added but on the grasped rows, and the force is F_lin exp(a p + b p^2) at
    the pull's length p (hand value: p = 5 mm, a = 0.02, b = 0.004: exp(0.1 + 0.1))."""
    from types import SimpleNamespace

    from surrogate.grasp import GraspForce, grasp_over_base

    calls = []

    class Placed:
        predictor = SimpleNamespace(grasp_force=GraspForce(a=0.02, b=0.004))

        def __call__(self, d, at, rest):
            calls.append((d.shape, at.tolist(), rest))
            return np.ones((1, 4, 3))

    base, f_lin = np.zeros((4, 3)), np.array([[1.0, 2.0, 0.0]])
    u, f = grasp_over_base(Placed(), [7], [[3.0, 4.0, 0.0]], base, f_lin, held=[1, 2])
    assert calls == [((1, 1, 3), [[7]], True)]
    assert np.array_equal(u, [[1, 1, 1], [0, 0, 0], [0, 0, 0], [1, 1, 1]])
    np.testing.assert_allclose(f, np.exp(0.2) * f_lin)
    # a law of the tool's distance to the fixed region: exp(0.2 + p r 0.001) at r = 10 mm
    Placed.predictor = SimpleNamespace(grasp_force=GraspForce(a=0.02, b=0.004, dist=0.001))
    f = grasp_over_base(Placed(), [7], [[3.0, 4.0, 0.0]], base, f_lin, dist=[10.0])[1]
    np.testing.assert_allclose(f, np.exp(0.25) * f_lin)
    with pytest.raises(ValueError, match="distance to the fixed region"):
        grasp_over_base(Placed(), [7], [[3.0, 4.0, 0.0]], base, f_lin)
    Placed.predictor = SimpleNamespace(grasp_force=None)   # a model without a force fit
    assert grasp_over_base(Placed(), [7], [[3.0, 4.0, 0.0]], base, f_lin)[1] is f_lin


def test_the_force_fit_recovers_a_known_stiffening_and_weighs_high_and_low_alike():
    """GraspForce.fit on forces made by a known law (any direction, any base size, any
    distance) gives its five coefficients back; two samples at one pull, 2x and 8x the base,
    fit 4x (the geometric mean: a relative fit would pick a factor nearer 2)."""
    from surrogate.grasp import GraspForce

    rng = np.random.default_rng(3)
    d = rng.normal(size=(40, 3)) * rng.uniform(1, 40, size=(40, 1))
    f_lin, r = rng.normal(size=(40, 3)), rng.uniform(20, 90, size=40)
    true = GraspForce(0.03, 0.0005, k=0.01, dist=-0.0002, cos=-0.02)
    fit = GraspForce.fit(d, f_lin, true(d, f_lin, r), r)
    np.testing.assert_allclose(dataclasses.astuple(fit), dataclasses.astuple(true), atol=1e-9)
    # without the distances: the law of the other four, its distance's coefficient 0
    assert GraspForce.fit(d, f_lin, GraspForce(0.03, 0.0005, k=0.01)(d, f_lin)).dist == 0.0
    d2, f2 = np.array([[10.0, 0, 0], [10.0, 0, 0]]), np.array([[1.0, 0, 0], [1.0, 0, 0]])
    fit = GraspForce.fit(d2, f2, f2 * [[2.0], [8.0]])
    assert abs(fit.factor(d2[0], f2[0]) - 4.0) < 1e-9


def test_a_force_held_by_the_tool_gives_the_pull_whose_force_it_is():
    """GraspForce.pull_for: for a random stiffness and forces from 0.01 to 4 N the law gives
    the force back at the pull found (to 1e-12 N); the base's law (all zero) gives K^-1 F
    exactly; no force, no pull; a law that softens beyond any pull is refused."""
    from surrogate.grasp import GraspForce

    rng = np.random.default_rng(11)
    a = rng.normal(size=(3, 3))
    k = 0.01 * a @ a.T + 0.02 * np.eye(3)   # N/mm, symmetric positive definite
    law = GraspForce(0.1, 4e-5, k=0.009, dist=-0.0002, cos=-0.02)
    for f in (np.array([0.01, 0.0, 0.0]), np.array([1.0, 2.0, -1.0]), np.array([3.0, -2.0, 1.0])):
        d = law.pull_for(k, f, 50.0)
        np.testing.assert_allclose(law(d, k @ d, 50.0), f, atol=1e-12)
        assert np.linalg.norm(d) < np.linalg.norm(np.linalg.solve(k, f))   # it stiffens
        np.testing.assert_allclose(GraspForce().pull_for(k, f), np.linalg.solve(k, f),
                                   rtol=1e-12)
    assert not np.any(law.pull_for(k, np.zeros(3), 50.0))
    with pytest.raises(ValueError, match="softens"):
        GraspForce(-1.0).pull_for(k, np.array([50.0, 0.0, 0.0]))


def test_the_force_law_turns_with_the_frame_and_is_the_base_at_small_pulls():
    """The law's inputs are the pull's length, the small-strain stiffness along it, the
    cosine between pull and force and a distance: turning the pull and the base's force by
    a rotation turns the force by it, whatever the coefficients; a pull of a micrometre gets
    the small-strain force (the factor within 5e-4 of 1, its gap shrinking with the pull at
    first order), as the FE does in that limit."""
    from scipy.spatial.transform import Rotation

    from surrogate.grasp import GraspForce

    rng = np.random.default_rng(5)
    law = GraspForce(0.1, 4e-5, k=0.009, dist=-0.0002, cos=-0.02)
    d, f_lin, r = rng.normal(size=(6, 3)) * 20.0, rng.normal(size=(6, 3)), np.full(6, 40.0)
    q = Rotation.random(random_state=7).as_matrix()
    np.testing.assert_allclose(law(d @ q.T, f_lin @ q.T, r), law(d, f_lin, r) @ q.T,
                               rtol=1e-12, atol=1e-12)
    tiny = 1e-3 * d / np.linalg.norm(d, axis=1, keepdims=True)
    gap = law.factor(tiny, 1e-3 * f_lin, r) - 1.0
    np.testing.assert_allclose(gap, 0.0, atol=5e-4)
    np.testing.assert_allclose(law.factor(0.1 * tiny, 1e-4 * f_lin, r) - 1.0, 0.1 * gap,
                               rtol=1e-2)
    assert np.all(law.factor(np.zeros((2, 3)), np.zeros((2, 3)), r[:2]) == 1.0)


@pytest.mark.dataset
def test_the_grasp_manipulator_moves_the_patch_to_the_pointer_and_shows_its_force(tmp_path):
    """make test's patient liver with its Green's function (make liver's kind of directory):
    a drag puts the grasped patch at the pointer (clamped at 40 mm), the field and the tool's
    force are the Green's function grasp's, the fixed region cannot be grasped, and the viewer
    draws it off screen; a directory without the function is refused naming it."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    from surrogate.manipulator import GraspManipulator
    from tests.surrogate.conftest import generated_dataset

    data = Path(generated_dataset("LIVERFEM_TEST_PATIENT")) / "data"
    m = GraspManipulator(data)
    node = m.handles[0].node
    tip = m.points[node] + [0.0, 0.0, 15.0]
    m.drag(tip)
    np.testing.assert_allclose(m.handle_position(), tip)
    frame = m.predict()
    patch = m._grasp.patches[0]
    np.testing.assert_allclose(frame.surface_u[m.surface.local(patch)],
                               np.broadcast_to([0.0, 0.0, 15.0], (patch.size, 3)), atol=1e-5)
    u, force = m._grasp(np.array([[0.0, 0.0, 15.0]]))
    np.testing.assert_allclose(frame.u, u)
    np.testing.assert_allclose(m.handles[0].force, force[0])
    assert force[0, 2] > 0   # pulled up, the tool pulls up
    m.drag(m.points[node] + [0.0, 0.0, 100.0])
    assert np.linalg.norm(m.pull) == pytest.approx(40.0)
    assert m.pick(m.points[m.fixed[0]]) == node   # the fixed region is not grasped
    out = tmp_path / "frames"
    res = subprocess.run([sys.executable, "-m", "surrogate.viewer", str(data), "--grasp",
                          "--offscreen", "--out", str(out), "--size", "320", "240"],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    timings = json.loads((out / "timings.json").read_text())
    assert timings["nodes_predicted"] == m.n_predicted and (out / "manipulator.gif").exists()
    res = subprocess.run([sys.executable, "-m", "surrogate.viewer", str(tmp_path), "--grasp",
                          "--offscreen", "--out", str(tmp_path / "none")],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 2 and "--grasp takes a liver's data directory" in res.stderr


@pytest.fixture(scope="module")
def grasp_run(tmp_path_factory):
    """make test's grasped phantoms (ci_grasp) and a population model over their small-strain
    base trained on them (3 folds by liver, the first evaluated)."""
    from surrogate.config import get_config
    from surrogate.train import train_and_evaluate
    from tests.surrogate.conftest import generated_dataset

    data = generated_dataset("LIVERFEM_TEST_GRASP")
    run = tmp_path_factory.mktemp("grasp") / "run"
    train_and_evaluate(data, run, get_config("population_green", folds=3, evaluate_folds=1,
                                             epochs=5, hidden=[16], ensemble=1, modes=4),
                       log_fn=lambda m: None)
    return data, run


@pytest.mark.dataset
def test_a_grasp_population_trains_over_its_small_strain_base(grasp_run):
    """Each sample's load is its tool's displacement at the step (the shard's record, mm) and
    its reaction force the shard's, the base of a sample holds the patch at that pull
    (fem_sim linear --population --order 1), a population model over it trains and exports,
    and it is refused where forces would be given it."""
    from data_spec import list_shards, read_geometry, read_shard
    from data_spec.eligible_loads import grasp_patch
    from data_spec.shards import geometry_path
    from surrogate import load_predictor
    from surrogate.data import load_dataset
    from surrogate.linear_base import PopulationLinearBase

    data, run = grasp_run
    ds = load_dataset(data)
    assert ds.load_kind == "grasp"
    sh = read_shard(list_shards(data)[5])
    at = np.flatnonzero(ds.sample_sim == sh.sim_index)
    np.testing.assert_allclose(ds.forces[at], sh.tool_displacement, rtol=1e-6)
    np.testing.assert_allclose(ds.reactions[at], sh.reaction)
    base = PopulationLinearBase(ds, order=1)
    g = read_geometry(geometry_path(data, sh.geometry_id))
    patch = grasp_patch(g.points, g.surface_nodes, sh.load_nodes[0], 10.0)
    for s in at:
        u = base.sample(ds, s)[np.searchsorted(ds.out_nodes[ds.sample_geo[s]], patch)]
        np.testing.assert_allclose(u, np.broadcast_to(ds.forces[s, 0], u.shape), atol=1e-3)
    with pytest.raises(ValueError, match="a model of grasps .* asked for forces: give it a grasp"):
        load_predictor(run / "model")
    assert load_predictor(run / "model", load="grasp").load == "grasp"


@pytest.mark.dataset
def test_the_models_force_beats_its_small_strain_base_on_the_held_out_livers(grasp_run):
    """The Ogden liver stiffens as a tool pulls it: fitted on the training livers, the force
    model's factor is above 1 and grows with the pull, and on the livers held out its force is
    nearer the FE reaction than the small-strain base's, over every pull and most on the
    large ones (beyond 20 mm, where the base is tens of % low)."""
    from surrogate import load_predictor
    from surrogate.data import load_dataset
    from surrogate.grasp import base_forces, heldout_grasp_force, tool_distances

    data, run = grasp_run
    law = load_predictor(run / "model", load="grasp").grasp_force
    ds = load_dataset(data)   # the first grasp's pull and force, scaled to 10, 20 and 30 mm
    d, f_lin = ds.forces[0, 0], base_forces(ds)[0, 0]
    scale = np.array([10.0, 20.0, 30.0])[:, None] / np.linalg.norm(d)
    stiffening = law.factor(scale * d, scale * f_lin, tool_distances(ds)[0, 0])
    assert 1.0 < stiffening[0] < stiffening[1] < stiffening[2]
    m = heldout_grasp_force(data, run)
    assert m["tools"] >= 30
    assert m["model"]["median_pct"] < m["base"]["median_pct"]
    assert m["model"]["large_median_pct"] < 0.8 * m["base"]["large_median_pct"]
    assert m["base"]["large_median_pct"] > 10.0   # the regime where the base is off


@pytest.mark.dataset
def test_a_model_of_grasps_answers_a_grasp_with_its_rest_and_its_force(grasp_run, tmp_path):
    """make test's patient liver with its Green's function: the grasp model placed on it adds
    its network's rest to the grasp's base (the patch still moves with the tool, the field
    elsewhere differs from the base's), gives the stiffened force (above the base's at a
    20 mm pull), and predict-liver writes both, saying the rest is the network's."""
    import json
    import warnings

    from surrogate import load_predictor
    from surrogate.__main__ import main
    from surrogate.evaluate import place
    from surrogate.over_green import OverGreen
    from tests.surrogate.conftest import generated_dataset

    _, run = grasp_run
    d = Path(generated_dataset("LIVERFEM_TEST_PATIENT"))
    liver = json.loads((d / "run" / "adaptation.json").read_text())["liver"]
    pred = load_predictor(run / "model", load="grasp")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        placement = place(pred, liver, None)[0]
    model = OverGreen(pred, d / "data", placement)
    g, free = model.geometry, model.green_nodes
    far = free[np.argmax(np.linalg.norm(g.points[free][:, None] - g.points[model.fixed_nodes]
                                        [None], axis=2).min(axis=1))]
    grasp = model.grasp([g.points[far]])
    pull = np.array([[0.0, 0.0, 20.0]])
    u, force = grasp(pull)
    u_base, force_base = grasp.base(pull)
    held = np.searchsorted(model.output_nodes, grasp.patches[0])
    np.testing.assert_allclose(u[held], np.broadcast_to(pull, (held.size, 3)), atol=1e-4)
    assert np.abs(u - u_base).max() > 1e-3   # the network's rest, off the patch
    assert np.linalg.norm(force) > np.linalg.norm(force_base)
    np.testing.assert_allclose(grasp.force(pull), force)
    o = tmp_path / "grasp"
    assert main(["predict-liver", str(run), liver, "--base", str(d / "data"), "--grasp",
                 *map(str, g.points[far]), *map(str, pull[0]), "--out", str(o),
                 "--no-picture"]) == 0
    summary = json.loads((o / "prediction.json").read_text())
    np.testing.assert_allclose(summary["forces_N"], force, rtol=1e-5)
    assert "network's rest" in summary["grasp"]
    # the viewer's grasping tool with the model: the same field and force at the same pull
    from surrogate.viewer import _parser, build

    args = _parser().parse_args([str(run), "--place", liver, "--base", str(d / "data"),
                                 "--grasp"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tool = build(args)[0]
    tool.pick(g.points[far])
    tool.set_force(pull[0])
    frame = tool.predict()
    np.testing.assert_allclose(frame.u, u, atol=1e-5)
    np.testing.assert_allclose(tool.handles[0].force, force[0], rtol=1e-5)
    assert "model of grasps" in tool.describe()
