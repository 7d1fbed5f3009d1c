"""A liver never seen (``predict-liver``), on a small population dataset that fem_sim generates
(make test: data_spec/scenes/ci_scene4.toml, 6 phantoms): the exported model carries its
shape model, places a liver of the population where the population put it, predicts on the
registered template, writes a ParaView file, and refuses bad files and single-liver models."""

import json
import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from liverviz.report import SOFA
from surrogate import load_predictor
from surrogate.__main__ import main
from surrogate.config import get_config
from surrogate.predict_liver import LiverFileError, predict_liver, read_liver_surface
from surrogate.train import train_and_evaluate
from tests.surrogate.conftest import generated_dataset

DATA = os.environ.get("LIVERFEM_TEST_DATASET4")
pytestmark = pytest.mark.dataset


@pytest.fixture(autouse=True, scope="module")
def _population_dataset():
    generated_dataset("LIVERFEM_TEST_DATASET4")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("pop_run")
    cfg = get_config("small", folds=2, epochs=4, hidden=[64, 64], batch_size=1024)
    train_and_evaluate(DATA, out, cfg, log_fn=lambda m: None)
    return out


def _population_liver(k: int):
    """(geometry file, its PCA coefficients) of liver k of the dataset's population."""
    with np.load(Path(DATA) / "geometry" / "population.npz") as z:
        gid, coeff = str(z["geometry_ids"][k]), z["coefficients"][k]
    return Path(DATA) / "geometry" / f"{gid}.h5", coeff


def test_the_export_carries_the_population(run):
    pred = load_predictor(run / "model")
    sm = pred.shape_model
    assert sm is not None and sm.n_components == pred.spec.geometry_dim == 3
    assert sm.template_cells.shape[1] == 4 and sm.loadable_nodes.size > 0
    assert np.all(np.isin(sm.fixed_nodes, sm.surface_nodes))
    with np.load(Path(DATA) / "geometry" / "population.npz") as z:
        np.testing.assert_array_equal(sm.population_coefficients, z["coefficients"][:, :3])


def test_a_liver_beyond_the_population_is_told_a_shape_inside_it(run):
    """A liver inside the population is told its own shape; one beyond it is told the design's
    rule's shape (node-wise: each coefficient clipped to the population's range) or the rule
    asked for (radius: scaled back onto the population's largest Mahalanobis radius): the
    prediction is the predictor's on the registered template told that shape, and says
    which."""
    import dataclasses

    from surrogate.predict_liver import place_liver, shape_rule

    pred = load_predictor(run / "model")
    assert pred.design == "nodewise" and shape_rule(pred) == "range"
    sm = pred.shape_model
    path, _ = _population_liver(3)
    points, tris = read_liver_surface(path)
    placed, _ = place_liver(pred, points, tris, center=False)
    C = sm.population_coefficients
    lo, hi = C.min(axis=0), C.max(axis=0)  # PCA coefficients: lo < 0 < hi
    inside = dataclasses.replace(placed, coefficients=0.9 * np.clip(placed.coefficients, lo, hi))
    radius = [np.linalg.norm(c / C.std(axis=0)) for c in (inside.coefficients, *C)]
    beyond = 2.0 * max(radius[1:]) / radius[0]  # twice the population's largest radius
    far = dataclasses.replace(inside, coefficients=beyond * inside.coefficients)
    node, f = sm.loadable_nodes[:1], [[0.0, 0.0, -0.4]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = [predict_liver(pred, points, tris, f, load_nodes=node, placement=pl, shape=rule)
               for pl, rule in ((inside, None), (far, None), (far, "radius"), (far, "hull"))]
    assert got[0].shape_rule == "own"
    np.testing.assert_array_equal(got[0].shape_told, inside.coefficients)
    for out, rule in zip(got[1:], ("range", "radius", "hull")):
        assert out.shape_rule == rule
        want, _ = sm.shape_told(far.coefficients, rule)
        np.testing.assert_allclose(out.shape_told, want)
        np.testing.assert_array_equal(out.coefficients, far.coefficients)
        direct = pred(f, node, geometry=(far.points, sm.fixed_nodes, want))
        np.testing.assert_allclose(out.displacement, direct, rtol=1e-5, atol=1e-6)
    assert np.all((got[1].shape_told >= lo) & (got[1].shape_told <= hi))
    assert np.any(got[1].shape_told != far.coefficients)
    np.testing.assert_allclose(np.linalg.norm(got[2].shape_told / C.std(axis=0)),
                               max(radius[1:]), rtol=1e-9)


def test_a_load_on_an_interior_node_is_flagged(run):
    pred = load_predictor(run / "model")
    sm = pred.shape_model
    path, _ = _population_liver(2)
    points, tris = read_liver_surface(path)
    interior = np.setdiff1d(np.arange(sm.template_points.shape[0]), sm.surface_nodes)[:1]
    with pytest.warns(UserWarning, match=rf"load node\(s\) \[{interior[0]}\] never loaded"):
        predict_liver(pred, points, tris, [[0.0, 0.0, -0.4]], load_nodes=interior)


@pytest.mark.skipif(not SOFA.exists(), reason=f"{SOFA} not present")
def test_the_command_on_a_real_liver_writes_paraview_and_the_numbers(run, tmp_path, capsys):
    out = tmp_path / "pl"
    assert main(["predict-liver", str(run), str(SOFA), "--force", "120", "100", "190", "0",
                 "0", "-0.4", "--out", str(out), "--no-picture"]) == 0
    summary = json.loads((out / "prediction.json").read_text())
    assert summary["registration_residual_mm"] > 0 and len(summary["shape_coefficients"]) == 3
    assert 0 < summary["max_displacement_mm"] < 100
    assert summary["shape_rule"] in ("own", "range") and len(summary["shape_told"]) == 3
    told_another = "the network is told a shape inside it" in capsys.readouterr().err
    assert told_another == (summary["shape_rule"] != "own")
    assert main(["predict-liver", str(run), str(SOFA), "--force", "120", "100", "190", "0",
                 "0", "-0.4", "--out", str(out), "--no-picture", "--shape", "own"]) == 0
    own = json.loads((out / "prediction.json").read_text())
    assert own["shape_rule"] == "own" and own["shape_told"] == own["shape_coefficients"]
    import pyvista as pv

    grid = pv.read(out / "liver_deformed.vtu")
    assert grid.n_points == load_predictor(run / "model").shape_model.template_points.shape[0]
    assert grid.point_data["displacement"].shape == (grid.n_points, 3)
    # the deformed liver lies where the file's liver lies (its own frame, not the population's)
    # (its bounding box within a fraction of the 20 mm template mesh)
    liver = read_liver_surface(SOFA)[0]
    assert np.abs(grid.points.min(axis=0) - liver.min(axis=0)).max() < 8.0
    assert np.abs(grid.points.max(axis=0) - liver.max(axis=0)).max() < 8.0


def test_bad_files_and_single_liver_models_are_refused(run, tmp_path, capsys):
    bad = tmp_path / "liver.txt"
    bad.write_text("not a liver")
    with pytest.raises(LiverFileError, match="liver.txt: unknown liver file type '.txt'"):
        read_liver_surface(bad)
    broken = tmp_path / "liver.stl"
    broken.write_bytes(b"solid x\nfacet broken\n")
    with pytest.raises(LiverFileError, match="liver.stl"):
        read_liver_surface(broken)
    path, _ = _population_liver(1)
    with pytest.raises(LiverFileError, match="if the file is in metres, give --scale-to-mm 1000"):
        read_liver_surface(path, scale_to_mm=1e-3)
    with pytest.raises(LiverFileError, match="too large for millimetres") as big:
        read_liver_surface(path, scale_to_mm=10.0)
    assert not re.search(r"\bmetres\b", str(big.value)) and "--scale-to-mm 0.1" in str(big.value)
    assert main(["predict-liver", str(run), str(bad), "--force", "0", "0", "0", "0", "0",
                 "-0.4"]) == 2
    assert "unknown liver file type" in capsys.readouterr().err
    assert main(["predict-liver", str(run), str(path), "--force", "0", "0", "0", "0", "0",
                 "-0.4", "--force", "0", "0", "0", "0", "0", "-0.4"]) == 2
    assert "takes 1 force(s), got 2" in capsys.readouterr().err


def test_a_model_of_one_liver_cannot_place_a_new_one(tmp_path, synth_dir, capsys):
    run = tmp_path / "one"
    train_and_evaluate(synth_dir, run, get_config("small", folds=2, epochs=1,
                                                  final_fit=True), log_fn=lambda m: None)
    assert main(["predict-liver", str(run), str(SOFA), "--force", "0", "0", "0", "0", "0",
                 "-0.4"]) == 2
    assert "trained on one liver" in capsys.readouterr().err


def test_predictions_at_a_livers_own_nodes_match_the_template_at_its_nodes(run):
    """Asked at the registered template's own nodes, predict_at_points gives the template's
    prediction back (the interpolation is exact at nodes)."""
    from surrogate.predict_liver import place_liver, predict_at_points

    pred = load_predictor(run / "model")
    sm = pred.shape_model
    path, _ = _population_liver(4)
    points, tris = read_liver_surface(path)
    placement, _ = place_liver(pred, points, tris)
    node = sm.loadable_nodes[:1]
    at = placement.to_liver(placement.points[node])
    got = predict_at_points(pred, placement, placement.to_liver(placement.points[:200]),
                            [[[0.0, 0.0, -0.4]]], at[None])
    want = placement.vectors_to_liver(pred(
        placement.vectors_to_population([[0.0, 0.0, -0.4]]), node,
        geometry=(placement.points, sm.fixed_nodes, placement.coefficients)))
    np.testing.assert_allclose(got[0], want[:200], rtol=1e-5, atol=1e-6)


def test_a_placed_model_predicts_many_cases_at_the_livers_nodes_as_one_by_one(run):
    """PlacedModel (placed once, called per frame): a batch of cases gives what each case
    gives alone; at a point inside a tetrahedron of the registered template's nodes the
    answer is the barycentric mix of its four nodes' (linear interpolation, by hand); on the
    nodes of the liver's own surface it agrees with predict_at_points."""
    from surrogate.predict_liver import PlacedModel, place_liver, predict_at_points

    pred = load_predictor(run / "model")
    sm = pred.shape_model
    path, _ = _population_liver(4)
    points, tris = read_liver_surface(path)
    placement, _ = place_liver(pred, points, tris)
    from scipy.spatial import Delaunay

    cell = Delaunay(placement.points).simplices[10]  # the interpolation's tetrahedra
    corners = placement.to_liver(placement.points[cell])
    inside = np.array([0.1, 0.2, 0.3, 0.4]) @ corners
    placed = PlacedModel(pred, nodes=np.vstack([corners, inside[None]]), placement=placement)
    at = placement.to_liver(placement.points[sm.loadable_nodes[:2]])
    nodes = placed.load_nodes(at[:, None])
    np.testing.assert_array_equal(nodes[:, 0], sm.loadable_nodes[:2])
    forces = np.array([[[0.0, 0.1, -0.4]], [[0.2, 0.0, -0.1]]])
    both = placed(forces, nodes)
    assert both.shape == (2, 5, 3)
    for k in range(2):
        np.testing.assert_allclose(both[k], placed(forces[k], nodes[k]), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(both[k, 4], [0.1, 0.2, 0.3, 0.4] @ both[k, :4],
                                   rtol=1e-5, atol=1e-6)
    on_surface = PlacedModel(pred, points, tris, placement=placement)
    np.testing.assert_allclose(on_surface(forces, nodes),
                               predict_at_points(pred, placement, points, forces, at[:, None]),
                               rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match="nodes"):
        PlacedModel(pred, placement=placement)


def test_a_turned_mirrored_liver_gets_the_same_prediction_in_its_own_frame(run):
    """Frame invariance: the file's frame changes nothing but the frame of the answer. A
    population liver turned by 50 degrees, mirrored (an LPS-like frame) and shifted is placed
    where the same liver as given is placed (the rigid fit finds the map), with the same
    shape coefficients; the force turned with it gives the displacement turned with it."""
    from surrogate.predict_liver import place_liver

    pred = load_predictor(run / "model")
    sm = pred.shape_model
    path, _ = _population_liver(2)
    points, tris = read_liver_surface(path)
    a = np.radians(50.0)
    A = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]) \
        @ np.diag([-1.0, 1.0, 1.0])
    b = np.array([150.0, -80.0, 40.0])
    turned = points @ A.T + b
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref, _ = place_liver(pred, points, tris, frame="auto")
        got, _ = place_liver(pred, turned, tris, frame="auto")
    assert got.mirrored and not ref.mirrored
    np.testing.assert_allclose(got.rotation @ A, ref.rotation, atol=1e-3)
    assert np.abs(got.points - ref.points)[sm.surface_nodes].max() < 0.5  # mm
    np.testing.assert_allclose(got.coefficients, ref.coefficients,
                               atol=0.02 * np.abs(ref.coefficients).max())
    f = np.array([[0.1, -0.25, -0.3]])
    node = sm.loadable_nodes[:1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        u_ref = predict_liver(pred, points, tris, f, load_nodes=node, placement=ref)
        u_got = predict_liver(pred, turned, tris, f @ A.T, load_nodes=node, placement=got)
    scale = np.abs(u_ref.displacement).max()
    np.testing.assert_allclose(u_got.displacement, u_ref.displacement @ A.T, atol=0.03 * scale)
    np.testing.assert_allclose(u_got.points, u_ref.points @ A.T + b, atol=0.5)
    # the template's cells keep their orientation in the mirrored frame: the inside-out ones
    # are those the registration folded, no more
    from data_spec.geometry import signed_volumes

    assert np.sum(signed_volumes(u_got.points, u_got.cells) <= 0) == u_got.inverted


def test_population_fields_move_to_the_template_and_back():
    """The population basis' one node order: the template's own fields go over exactly, any
    other liver's come back from the registered template within a few % (measured 0.6-2.6 %
    on this population; linear interpolation both ways)."""
    from surrogate.data import load_dataset
    from surrogate.population_basis import TemplateFields

    ds = load_dataset(DATA)
    maps = TemplateFields(ds)
    with np.load(Path(DATA) / "geometry" / "population.npz") as z:
        template = str(z["geometry_ids"][0])
    for g, gid in enumerate(ds.geo_ids):
        s = np.flatnonzero(ds.sample_geo == g)[-1]
        u = np.asarray(ds.targets[ds.sample_offset[s]:ds.sample_offset[s + 1]], float)
        back = maps.to_liver[g] @ (maps.to_template[g] @ u)
        rel = np.linalg.norm(back - u, axis=1).mean() / np.linalg.norm(u, axis=1).mean()
        assert rel < (1e-12 if gid == template else 0.06), (gid, rel)
        assert maps.fields(ds, [s]).shape == (1, 3 * maps.n_template)


def test_the_population_basis_predicts_a_new_liver_on_its_template(tmp_path, synth_dir):
    from surrogate.population_basis import BasisDesignError

    run = tmp_path / "pb"
    cfg = get_config("population_basis", folds=2, epochs=20, modes=16, hidden=[32],
                     load_context=True, ensemble=1)  # one network: the next test, two
    result = train_and_evaluate(DATA, run, cfg, log_fn=lambda m: None)
    assert np.isfinite(result["network"]["mee"]) and result["n_simulations"] == 36
    pred = load_predictor(run / "model")
    assert pred.design == "population_basis" and pred.shape_model is not None
    path, _ = _population_liver(2)
    points, tris = read_liver_surface(path)
    out = predict_liver(pred, points, tris, [[0.0, 0.0, -0.4]],
                        load_nodes=pred.shape_model.loadable_nodes[:1])
    assert out.displacement.shape == pred.shape_model.template_points.shape
    assert np.all(np.isfinite(out.displacement)) and np.abs(out.displacement).max() > 0
    with pytest.raises(ValueError, match="predicts on the registered template"):
        pred([[0.0, 0.0, -0.4]], [0], geometry=(points, [0], out.coefficients))
    with pytest.raises(BasisDesignError, match="needs a scene that varies the liver"):
        train_and_evaluate(synth_dir, tmp_path / "one", cfg, log_fn=lambda m: None)


def test_the_population_basis_refuses_a_dataset_without_its_registration(tmp_path):
    """The scene-4 dataset without DATA/geometry/population.npz: the design names the file it
    needs before any training."""
    from surrogate.population_basis import BasisDesignError

    bare = tmp_path / "bare"
    (bare / "geometry").mkdir(parents=True)
    for p in Path(DATA).iterdir():
        if p.name != "geometry":
            (bare / p.name).symlink_to(p.resolve())
    for p in (Path(DATA) / "geometry").iterdir():
        if p.name != "population.npz":
            (bare / "geometry" / p.name).symlink_to(p.resolve())
    cfg = get_config("population_basis", folds=2, epochs=1, modes=4, hidden=[8], ensemble=1)
    with pytest.raises(BasisDesignError, match=r"registration \(.*bare/geometry/population.npz\)"):
        train_and_evaluate(bare, tmp_path / "run", cfg, log_fn=lambda m: None)


def test_the_population_basis_exports_what_it_trained(tmp_path):
    """The exported predictor computes what training computes from the same inputs (the
    template's own mesh, loads at template nodes, whose place on the template is the node
    itself), reads only the shape coefficients it was told (``shape_inputs``) and reads the
    load context (another fixed region, another prediction); as an ensemble of two, the
    shipped config's form."""
    from types import SimpleNamespace

    from surrogate.basis import predict_fields
    from surrogate.data import load_dataset
    from surrogate.export import export_model
    from surrogate.population_basis import load_context
    from surrogate.train import fit_design

    ds = load_dataset(DATA)
    cfg = get_config("population_basis", epochs=5, modes=8, hidden=[16], load_context=True,
                     shape_inputs=2, ensemble=2)
    model, _ = fit_design(ds, np.arange(ds.n_samples), cfg, 0, log_fn=lambda m: None)
    assert (model.n_extra, model.context, model.members) == (ds.spec.material_dim + 2, 7, 2)
    pred = load_predictor(export_model(tmp_path / "m", model, cfg, ds))
    sm = pred.shape_model
    T, fixed = sm.template_points, sm.fixed_nodes
    nodes = sm.loadable_nodes[[0, 5, 11]][:, None]
    forces = np.random.default_rng(0).normal(scale=0.1, size=(3, ds.spec.n_loads, 3))
    shape = ds.extra[0, ds.spec.material_dim:].astype(np.float64)
    got = pred(forces, nodes, geometry=(T, fixed, shape))
    inputs = SimpleNamespace(forces=forces, load_points=T[nodes],
                             extra=np.broadcast_to(ds.extra[0], (3, ds.extra.shape[1])))
    ctx = load_context(T[nodes], T[nodes], T[fixed])
    want = predict_fields(inputs, model, np.arange(3), ctx).reshape(got.shape)
    assert np.abs(want).max() > 0
    np.testing.assert_allclose(got, want, atol=1e-4 * np.abs(want).max())
    later, first = shape.copy(), shape.copy()
    later[2:] += 100.0
    first[0] += 100.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # outside the population's range: warned, on purpose
        np.testing.assert_array_equal(pred(forces, nodes, geometry=(T, fixed, later)), got)
        assert np.abs(pred(forces, nodes, geometry=(T, fixed, first)) - got).max() > 1e-4
    other = np.setdiff1d(np.arange(40), nodes)[:10]
    assert np.abs(pred(forces, nodes, geometry=(T, other, shape)) - got).max() > 1e-4


def test_the_load_context_by_hand():
    """Two fixed points (0,0,0) and (2,0,0), centroid (1,0,0); a load at (1,3,0): offset
    (0,3,0), distance sqrt(1 + 9) to either; its place on the template passes through."""
    from surrogate.population_basis import load_context

    F = np.array([[0.0, 0, 0], [2, 0, 0]])
    ctx = load_context([[[1.0, 3, 0]]], [[[7.0, 8, 9]]], F)
    np.testing.assert_allclose(ctx, [[[7, 8, 9, 0, 3, 0, np.sqrt(10)]]])


@pytest.mark.skipif(not SOFA.exists(), reason=f"{SOFA} not present")
def test_the_manipulator_opens_on_a_placed_liver(run, tmp_path):
    """predict-liver without --force opens the manipulator on the placed liver; off-screen,
    the same placement drives its frames."""
    from surrogate.viewer import main as viewer

    out = tmp_path / "vw"
    assert viewer([str(run), "--place", str(SOFA), "--offscreen", "--out", str(out)]) == 0
    assert (out / "manipulator.gif").stat().st_size > 0
    assert viewer([str(run), "--place", str(tmp_path / "none.stl"), "--offscreen", "--out",
                   str(out)]) == 2


def test_shape_noise_perturbs_only_the_shape_coefficients():
    """shape_noise sets the training noise of the shape coefficients (the features' last
    columns) apart from input_noise, which keeps the loads'; without it every feature takes
    input_noise. It perturbs training steps only, and only the population design takes it."""
    import jax

    from surrogate.data import load_dataset
    from surrogate.designs import DESIGNS

    ds = load_dataset(DATA)
    design = DESIGNS["population_basis"]
    rng = np.random.default_rng(0)
    tr, va = np.arange(ds.n_samples - 6), np.arange(ds.n_samples - 6, ds.n_samples)

    def problem(**over):
        cfg = get_config("population_basis", modes=4, hidden=[8], shape_inputs=2, **over)
        return design.problem(ds, tr, va, cfg, rng)

    apart = problem(input_noise=0.0, shape_noise=0.7)
    width = apart.data["x"].shape[1]
    want = np.zeros(width, np.float32)
    want[-2:] = 0.7  # the two shape coefficients it is told, after the loads and the material
    np.testing.assert_array_equal(np.asarray(apart.noise), want)
    both = problem(input_noise=0.2, shape_noise=0.7)
    want[:-2] = 0.2
    np.testing.assert_array_equal(np.asarray(both.noise), want)
    np.testing.assert_array_equal(np.asarray(problem(input_noise=0.2).noise),
                                  np.full(width, 0.2, np.float32))
    assert problem(input_noise=0.0).noise is None
    params = apart.init(jax.random.PRNGKey(0))
    idx, key = apart.batch(tr[:8]), jax.random.PRNGKey(1)
    clean = problem(input_noise=0.0)
    assert float(apart.loss(params, apart.data, idx, key, False)) == pytest.approx(
        float(clean.loss(params, clean.data, idx, key, True)), rel=1e-6)
    assert float(apart.loss(params, apart.data, idx, key, True)) != pytest.approx(
        float(clean.loss(params, clean.data, idx, key, True)), rel=1e-3)
    for d in ("nodewise", "basis"):
        with pytest.raises(ValueError, match=f"shape_noise: the {d} design does not take it, "
                           "only population_basis"):
            get_config("small", design=d, shape_noise=0.5)
    with pytest.raises(ValueError, match="shape_noise: expected null or a finite number >= 0"):
        get_config("population_basis", shape_noise=-1.0)


def test_the_truth_of_a_liver_carries_the_models_fixed_region_and_is_evaluated(run, tmp_path,
                                                                                capsys):
    """truth-scene: the population scene's settings on one liver file, fixed at the points
    where the model's placement puts the template's fixed region; evaluate_liver on that
    liver's own simulations of the population (as if they were its truth) reports the model
    and the naive model on them."""
    from data_spec import load_scene
    from data_spec.geometry import read_geometry
    from surrogate.evaluate import evaluate_liver, place

    liver, _ = _population_liver(1)
    out = tmp_path / "truth.toml"
    assert main(["truth-scene", str(run), str(liver), "--scene", str(Path(DATA) / "scene.toml"),
                 "--sims", "3", "--frame", "population", "--out", str(out)]) == 0
    scene = load_scene(out)
    assert scene["geometry"]["source"] == "file" and scene["scene"]["n_simulations"] == 3
    assert scene["fixed"]["kind"] == "points"
    pred = load_predictor(run / "model")
    placement, found = place(pred, liver, "population")
    fixed_points = np.asarray(scene["fixed"]["points"])
    want = placement.to_liver(placement.points[pred.shape_model.fixed_nodes])
    np.testing.assert_allclose(fixed_points, want, atol=1e-3)
    gid = read_geometry(liver).geometry_id
    m = evaluate_liver(pred, Path(DATA), placement, found, geometry_id=gid)
    assert m["sims"] == 6 and np.isfinite(m["skill"]) and m["inverted"] == placement.inverted
    assert "modes_floor_mm" not in m  # a node-wise model has no modes


def test_a_force_off_the_liver_is_said_or_refused_before_the_registration(run, tmp_path,
                                                                          capsys):
    """A force point 12 mm outside the liver is moved to the nearest surface node with a
    warning, and prediction.json records the point asked for, the point used and the move; a
    point 1.6 m away, and an --out that is a file, are refused with exit 2 before any
    registration (nothing written)."""
    from surrogate.predict_liver import REFUSE_MM, WARN_MM

    liver = read_liver_surface(SOFA)[0]
    tip = liver[np.argmax(liver[:, 0])] + [12.0, 0.0, 0.0]  # beyond the largest x
    out = tmp_path / "pl"
    assert main(["predict-liver", str(run), str(SOFA), "--force", *map(str, tip), "0", "0",
                 "-0.4", "--out", str(out), "--no-picture"]) == 0
    err = capsys.readouterr().err
    assert f"is 12.0 mm from the surface of {SOFA} (more than {WARN_MM:g} mm)" in err
    s = json.loads((out / "prediction.json").read_text())
    np.testing.assert_allclose(s["force_points_asked_mm"], [tip])
    moved = np.linalg.norm(np.subtract(s["force_points_used_mm"], [tip]), axis=1)
    np.testing.assert_allclose(s["force_point_moved_mm"], moved)
    assert 10.0 < moved[0] < 30.0 and any("12.0 mm from the surface" in w for w in s["warnings"])
    far = liver.max(axis=0) + 1600.0
    assert main(["predict-liver", str(run), str(SOFA), "--force", *map(str, far), "0", "0",
                 "-0.4", "--out", str(tmp_path / "far"), "--no-picture"]) == 2
    err = capsys.readouterr().err
    assert f"more than {REFUSE_MM:g} mm, not a point of this liver" in err
    assert "registering" not in err and not (tmp_path / "far").exists()  # nothing created
    (tmp_path / "a_file").write_text("")
    assert main(["predict-liver", str(run), str(SOFA), "--force", *map(str, tip), "0", "0",
                 "-0.4", "--out", str(tmp_path / "a_file"), "--no-picture"]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "is a file; expected a directory" in err
    assert "registering" not in err


def test_two_livers_in_one_file_are_refused_naming_both_volumes(tmp_path):
    """Issue 81: predict-liver kept the larger of two livers in one file without a word."""
    from surrogate.predict_liver import LiverFileError, read_liver_surface

    p, t = read_liver_surface(SOFA)
    q = p + [np.ptp(p[:, 0]) + 10.0, 0.0, 0.0]
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in np.concatenate([p, q])]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.concatenate([t, t + len(p)])]
    (tmp_path / "two.obj").write_text("\n".join(lines) + "\n")
    with pytest.raises(LiverFileError, match=r"2 separate pieces: the largest encloses (\d+) mL, "
                                             r"the next \1 mL.*--keep-largest"):
        read_liver_surface(tmp_path / "two.obj")
