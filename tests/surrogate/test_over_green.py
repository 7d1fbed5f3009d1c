"""A new liver over its own Green's function (``make liver``, :mod:`surrogate.over_green`):
make test's patient liver (Amos-004, outside the three-liver population) with its Green's
function from ``make patient``'s ``fem_sim linear --green``, and a population model of the
rest over each liver's linear response trained on the three livers."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from surrogate import load_predictor
from surrogate.data import load_dataset
from surrogate.metrics import mee as field_mee
from surrogate.patient import sample_fields, sims_samples
from tests.surrogate.conftest import generated_dataset

pytestmark = pytest.mark.dataset


@pytest.fixture(scope="module")
def patient():
    """(patient directory, its adaptation.json, the three-liver population's rest model)."""
    import os
    import tempfile

    from surrogate.config import get_config
    from surrogate.train import train_and_evaluate

    d = Path(generated_dataset("LIVERFEM_TEST_PATIENT"))
    livers = os.environ.get("LIVERFEM_TEST_LIVERS")
    assert livers, "LIVERFEM_TEST_LIVERS not set: make test sets it"
    run = Path(tempfile.mkdtemp()) / "green"
    train_and_evaluate(livers, run, get_config(
        "population_green", folds=3, evaluate_folds=1, epochs=40, hidden=[64, 64],
        ensemble=1, modes=16), log_fn=lambda m: None)
    return d, json.loads((d / "run" / "adaptation.json").read_text()), run


def _placed(pred, d, info):
    from surrogate.evaluate import place

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return place(pred, info["liver"], None, d / "placement.npz")[0]


def test_the_greens_function_gives_each_loads_own_linear_solve_and_the_rest_is_added(patient,
                                                                                     tmp_path):
    """The linear part of each FE simulation's load, contracted from the unit responses, is
    the response fem_sim linear solved for that load itself (another right-hand side of the
    same factorisation: they agree to the solves' tolerance, 1e-6 relative), and the model's
    field less the same model's over a Green's function of zeros (the network's rest alone)
    is that solve too."""
    from surrogate.linear_base import LinearBase
    from surrogate.over_green import OverGreen

    d, info, run = patient
    rest = load_predictor(run / "model")
    model = OverGreen(rest, d / "data", _placed(rest, d, info))
    ds = load_dataset(d / "data")
    lb = LinearBase(ds)
    sims = np.unique(ds.sample_sim)
    rows = lb.lf.rows(sims)
    forces, nodes = lb.lf.forces[rows], lb.lf.load_nodes[rows]
    solved = lb.lf.displacement[rows][:, lb.columns].astype(np.float64)
    green = model.linear(forces, nodes)[:, np.searchsorted(model.output_nodes, ds.out_nodes[0])]
    scale = np.abs(solved).max()
    assert np.abs(green - solved).max() < 1e-4 * scale, np.abs(green - solved).max() / scale
    # the same model over a Green's function of zeros gives the network's rest alone: what
    # the true one adds to it is each load's own linear solve (fem_sim linear's, independent)
    import shutil

    import h5py

    zero = shutil.copytree(d / "data", tmp_path / "zero")
    with h5py.File(zero / "linear.h5", "r+") as f:
        f["green"][...] = 0.0
    rest_alone = OverGreen(rest, zero, _placed(rest, d, info))(forces, nodes)
    cols = np.searchsorted(model.output_nodes, ds.out_nodes[0])
    added = (model(forces, nodes) - rest_alone)[:, cols]
    np.testing.assert_allclose(added, solved, rtol=0, atol=1e-4 * scale)
    assert np.abs(rest_alone).max() > 1e-3 * scale   # and the network's rest is not nothing


def test_a_new_liver_over_its_greens_function_beats_the_placed_population_model(patient,
                                                                                tmp_path):
    """On the patient's FE simulations (none trained on), the model over the liver's own
    Green's function is far closer to FE than the population basis placed alone, and the
    command writes the whole liver with the model's field at the load."""
    from surrogate.__main__ import main
    from surrogate.over_green import OverGreen
    from surrogate.predict_liver import PlacedModel

    d, info, run = patient
    rest, population = load_predictor(run / "model"), load_predictor(info["population_model"])
    ds = load_dataset(d / "data")
    smp = sims_samples(ds, np.unique(ds.sample_sim))
    true = sample_fields(ds, smp)
    out = np.asarray(ds.out_nodes[0])
    model = OverGreen(rest, d / "data", _placed(rest, d, info))
    ours = model(ds.forces[smp], ds.load_nodes[smp])[:, np.searchsorted(model.output_nodes,
                                                                          out)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        placed = PlacedModel(population, nodes=ds.points[0],
                             placement=_placed(population, d, info))
        alone = placed(ds.forces[smp], placed.load_nodes(ds.load_points[smp]))[:, out]
    print(f"MEE over the Green's function {field_mee(ours, true):.3f} mm, population model "
          f"alone {field_mee(alone, true):.3f} mm")
    assert field_mee(ours, true) < 0.5 * field_mee(alone, true)
    s = smp[-1]   # a simulation's last load step through the command
    at, f = ds.load_points[s, 0], ds.forces[s, 0]
    o = tmp_path / "prediction"
    assert main(["predict-liver", str(run), info["liver"], "--base", str(d / "data"),
                 "--placement", str(d / "placement.npz"), "--force", *map(str, at),
                 *map(str, f), "--out", str(o), "--no-picture"]) == 0
    summary = json.loads((o / "prediction.json").read_text())
    assert summary["load_nodes"] == [int(ds.load_nodes[s, 0])]
    assert np.isclose(summary["max_displacement_mm"],
                      np.linalg.norm(model(f[None], ds.load_nodes[s]), axis=1).max(), rtol=1e-5)
    assert (o / "liver_deformed.vtu").exists()


def test_a_model_without_a_linear_rest_is_refused_naming_what_to_run(patient, capsys,
                                                                     tmp_path, monkeypatch):
    """Models over no base or a second-order one cannot use the Green's function alone: each
    refused with what to do instead; a dataset without the function names fem_sim linear,
    and predict-liver of the rest model without --base names make liver. With --base and no
    load, predict-liver opens the manipulator over the Green's function (no --no-center)."""
    import surrogate.viewer
    from surrogate.__main__ import main
    from surrogate.over_green import OverGreen

    d, info, run = patient
    population = load_predictor(info["population_model"])
    with pytest.raises(ValueError, match="predict-liver places it without a base"):
        OverGreen(population, d / "data", _placed(population, d, info))
    rest = load_predictor(run / "model")
    with pytest.raises(ValueError, match="linear.h5: missing; run `fem_sim linear"):
        OverGreen(rest, d, _placed(rest, d, info))
    opened = []
    monkeypatch.setattr(surrogate.viewer, "main", lambda argv: opened.append(argv) or 0)
    base = ["predict-liver", str(run), info["liver"], "--base", str(d / "data")]
    assert main(base) == 0
    assert opened == [[str(run), "--place", info["liver"], "--base", str(d / "data")]]
    assert main(base + ["--no-center"]) == 2 and len(opened) == 1
    assert "no --no-center" in capsys.readouterr().err
    assert main(["predict-liver", str(run), info["liver"], "--force", "0", "0", "0", "0", "0",
                 "-0.4", "--out", str(tmp_path / "nothing"), "--no-picture"]) == 2
    assert "make liver LIVER=... MODEL=<this run>" in capsys.readouterr().err


def test_another_livers_directory_or_scene_is_refused_naming_both(patient, capsys, tmp_path):
    """Issue 81: predict-liver --base of another liver's directory (or a linear.h5 of another
    scene) was silently wrong: OverGreen took whatever geometry the file named."""
    import shutil

    import h5py

    from surrogate.__main__ import main
    from surrogate.over_green import OverGreen
    from surrogate.predict_liver import read_liver_surface

    d, info, run = patient
    other = str(Path(info["liver"]).with_name("LiTS-12.obj"))
    at = read_liver_surface(other)[0][0]   # a point on the other liver's surface
    force = ["--force", *map(str, at), "0", "0", "-0.4", "--no-picture"]
    assert main(["predict-liver", str(run), other, "--base", str(d / "data"), *force,
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"holds the mesh of another liver than {other}" in err and "Traceback" not in err
    data = shutil.copytree(d / "data", tmp_path / "data")
    with h5py.File(data / "linear.h5", "r+") as f:
        f.attrs["scene_hash"] = "0" * 64
    rest = load_predictor(run / "model")
    with pytest.raises(ValueError, match="another scene's responses"):
        OverGreen(rest, data, _placed(rest, d, info))


def test_the_evaluation_of_an_unseen_liver_adds_the_base_and_reports_it_alone(patient,
                                                                              tmp_path):
    """``surrogate.evaluate.evaluate_unseen`` (the evaluate command's, the benches') on the
    patient's truth with the model of the rest over the linear response: its MEE is the MEE
    of make liver's field (OverGreen, another code path) against the FE fields, and the base
    alone's is that of each simulation's own linear solve (fem_sim linear's, read from the
    file) scaled by the load fraction, against the same fields."""
    import shutil

    from surrogate.evaluate import evaluate_unseen
    from surrogate.linear_base import LinearBase
    from surrogate.over_green import OverGreen

    d, info, run = patient
    truth = tmp_path / "truth"   # a copy: the evaluation may build the base in it
    shutil.copytree(d / "data", truth / "data")
    shutil.copy(d / "scene.toml", truth / "scene.toml")
    rest = load_predictor(run / "model")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = evaluate_unseen(rest, truth / "data", info["liver"], None)
    ds = load_dataset(d / "data")
    smp = sims_samples(ds, np.unique(ds.sample_sim))
    true = sample_fields(ds, smp)
    model = OverGreen(rest, d / "data", _placed(rest, d, info))
    ours = model(ds.forces[smp], ds.load_nodes[smp])[
        :, np.searchsorted(model.output_nodes, ds.out_nodes[0])]
    assert np.isclose(got["network"]["mee"], field_mee(ours, true), rtol=1e-4)
    lb = LinearBase(ds)
    rows = lb.lf.rows(ds.sample_sim[smp])
    solved = lb.lf.displacement[rows][:, lb.columns].astype(np.float64)
    alone = ds.sample_fraction[smp][:, None, None] * solved
    assert got["base_alone"]["order"] == 1
    assert np.isclose(got["base_alone"]["network"]["mee"], field_mee(alone, true), rtol=1e-4)


def test_a_grasp_over_the_greens_function_holds_its_patch_and_gives_the_force_back(patient,
                                                                                   tmp_path):
    """make liver GRASP=...: the tool's patch (the solver's rule) follows the tool; the field
    is the Green's function's response to the patch's nodal forces (the contraction every
    load's linear part is) and the force their sum, doing positive work; the base is linear
    (twice the pull, twice both); a patch that reaches the fixed region is refused naming the
    node; the command writes the tool's force."""
    from surrogate.__main__ import main
    from surrogate.over_green import OverGreen

    d, info, run = patient
    rest = load_predictor(run / "model")
    model = OverGreen(rest, d / "data", _placed(rest, d, info))
    g, free = model.geometry, model.green_nodes
    far = free[np.argmax(np.linalg.norm(g.points[free][:, None] - g.points[model.fixed_nodes]
                                        [None], axis=2).min(axis=1))]
    grasp = model.grasp([g.points[far]])
    pull = np.array([[3.0, -4.0, 10.0]])
    u, force = grasp(pull)
    patch = grasp.patches[0]
    assert far in patch and patch.size > 1
    np.testing.assert_allclose(u[np.searchsorted(model.output_nodes, patch)],
                               np.broadcast_to(pull, (patch.size, 3)), atol=1e-6 * 10)
    nodal = grasp.nodal_forces @ pull.ravel()
    np.testing.assert_allclose(model.linear(nodal[None], patch[None])[0], u,
                               atol=1e-6 * np.abs(u).max())
    np.testing.assert_allclose(force[0], nodal.sum(axis=0), rtol=1e-9)
    assert force[0] @ pull[0] > 0 and np.all(np.linalg.eigvalsh(grasp.stiffness) > 0)
    u2, force2 = grasp(2 * pull)
    np.testing.assert_allclose(u2, 2 * u, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(force2, 2 * force, rtol=1e-9)
    with pytest.raises(ValueError, match="has no unit response"):
        model.grasp([g.points[model.fixed_nodes[0]]], radius=40.0)
    o = tmp_path / "grasp"
    assert main(["predict-liver", str(run), info["liver"], "--base", str(d / "data"),
                 "--placement", str(d / "placement.npz"), "--grasp", *map(str, g.points[far]),
                 *map(str, pull[0]), "--out", str(o), "--no-picture"]) == 0
    summary = json.loads((o / "prediction.json").read_text())
    np.testing.assert_allclose(summary["forces_N"], force, rtol=1e-6)
    assert summary["grasp_displacements_mm"] == pull.tolist()


def _near_copy(d: Path, whole, tmp_path: Path) -> tuple[Path, int, int]:
    """(a copy of the liver's data directory holding the unit responses within 20 mm of the
    free node farthest from the fixed region, as make liver solves them; that node, a free
    node beyond them).
    """
    import shutil

    import h5py

    g, free = whole.geometry, whole.green_nodes
    far = free[np.argmax(np.linalg.norm(g.points[free][:, None] - g.points[whole.fixed_nodes]
                                        [None], axis=2).min(axis=1))]
    keep = np.linalg.norm(g.points[free] - g.points[far], axis=1) <= 20.0
    part = shutil.copytree(d / "data", tmp_path / "near")
    with h5py.File(part / "linear.h5", "r+") as f:
        green = f["green"][()][keep]
        for name in ("green", "green_nodes"):
            del f[name]
        f["green_nodes"], f["green"] = free[keep], green
        if "fixed_nodes" not in f:   # a file of before they were recorded
            f["fixed_nodes"] = whole.fixed_nodes
    return part, far, free[~keep][0]


def test_a_greens_function_near_the_grasp_answers_it_and_refuses_elsewhere(patient, tmp_path):
    """make liver's Green's function near its load only (fem_sim linear --green-near): the
    grasp there gets the whole surface's answer, its fixed region read from the file; a load
    on the free surface beyond it is refused naming the flag, not answered from the nearest
    computed node (a silent wrong field), and the manipulator without a solver says so."""
    from surrogate.manipulator import GraspManipulator
    from surrogate.over_green import OverGreen

    d, info, run = patient
    rest = load_predictor(run / "model")
    whole = OverGreen(rest, d / "data", _placed(rest, d, info))
    part, far, other = _near_copy(d, whole, tmp_path)
    g = whole.geometry
    near = OverGreen(rest, part, _placed(rest, d, info))
    np.testing.assert_array_equal(near.fixed_nodes, whole.fixed_nodes)
    pull = np.array([[3.0, -4.0, 10.0]])
    for a, b in zip(near.grasp([g.points[far]])(pull), whole.grasp([g.points[far]])(pull)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.abs(b).max())
    with pytest.raises(ValueError, match="--green-near"):
        near.grasp([g.points[other]])
    with pytest.raises(ValueError, match="--green-near"):
        near([[0.0, 0.0, -0.3]], [other])
    np.testing.assert_allclose(near([[0.0, 0.0, -0.3]], [far]),
                               whole([[0.0, 0.0, -0.3]], [far]), atol=1e-9)
    with pytest.raises(ValueError, match="--solver"):
        GraspManipulator(part)


def test_a_patch_beyond_make_livers_responses_is_solved_when_grasped(patient, tmp_path):
    """With the solver's python (make manipulate): the patch's unit responses are solved by
    a solver process when grasped, once, and answer as the whole file does (the same
    factorisation's back-solves), for the model and for the manipulator's base alone."""
    from surrogate.manipulator import GraspManipulator
    from surrogate.over_green import OverGreen

    d, info, run = patient
    rest = load_predictor(run / "model")
    whole = OverGreen(rest, d / "data", _placed(rest, d, info))
    part, _, other = _near_copy(d, whole, tmp_path)
    at, pull = whole.geometry.points[other], np.array([[3.0, -4.0, 10.0]])
    u, force = whole.grasp([at])(pull)   # a model of forces grasps with the base
    solver = str(Path(__file__).resolve().parents[2] / ".venv-solver" / "bin" / "python")
    live = OverGreen(rest, part, _placed(rest, d, info), solver=solver)
    try:
        assert live.whole_surface_problem() == ""
        for a, b in zip(live.grasp([at])(pull), (u, force)):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5 * np.abs(b).max())
        live.grasp([at])
        assert len(live._grow.seconds) == 1   # solved once
    finally:
        live.close()
    m = GraspManipulator(part, solver=solver)
    try:
        assert m.pick(at) == other
        m.drag(at + pull[0])
        frame = m.predict()
        np.testing.assert_allclose(frame.u, u, rtol=1e-5, atol=1e-5 * np.abs(u).max())
        np.testing.assert_allclose(m.handles[0].force, force[0], rtol=1e-5)
        assert len(m.solved_seconds) >= 1
    finally:
        m.close()


def test_the_window_solves_every_patch_in_the_background_and_a_grasp_finds_it(patient,
                                                                             tmp_path):
    """The window's prefetch (a second solver process while people look): the free surface's
    unit responses solved in the background, nearest the tool first; a grasp asked meanwhile
    is answered by the first process, one afterwards needs no request of its own, and every
    row is the whole file's (the same factorisation's back-solves), none twice."""
    import time

    from surrogate.manipulator import GraspManipulator
    from surrogate.over_green import OverGreen

    d, info, run = patient
    rest = load_predictor(run / "model")
    whole = OverGreen(rest, d / "data", _placed(rest, d, info))
    part, _, other = _near_copy(d, whole, tmp_path)
    at, pull = whole.geometry.points[other], np.array([[3.0, -4.0, 10.0]])
    u, force = whole.grasp([at])(pull)
    solver = str(Path(__file__).resolve().parents[2] / ".venv-solver" / "bin" / "python")
    m = GraspManipulator(part, solver=solver)
    try:
        m.prefetch()
        assert m._grow.prefetching
        first = m.default_nodes(3)[-1]
        m.pick(m.points[first])   # while the background works: answered
        assert m.handles[0].node == first
        t = time.perf_counter()
        while m._grow.prefetching and time.perf_counter() - t < 300:
            time.sleep(0.05)
        asked = len(m.solved_seconds)
        assert m.pick(at) == other and len(m.solved_seconds) == asked   # found solved
        m.drag(at + pull[0])
        np.testing.assert_allclose(m.predict().u, u, rtol=1e-5, atol=1e-5 * np.abs(u).max())
        np.testing.assert_allclose(m.handles[0].force, force[0], rtol=1e-5)
        lf = m._lf
        assert m._grow.prefetch_error is None and m._grow.prefetch_seconds > 0
        assert np.array_equal(np.sort(lf.green_nodes), np.sort(whole.green_nodes))
        row = {int(n): i for i, n in enumerate(whole.green_nodes)}
        order = [row[int(n)] for n in lf.green_nodes]
        np.testing.assert_allclose(lf.green, whole._lf.green[order], rtol=1e-5,
                                   atol=1e-5 * np.abs(whole._lf.green).max())
    finally:
        m.close()


def test_a_background_that_cannot_open_leaves_the_grasps_answered(patient, tmp_path,
                                                                  monkeypatch):
    """The prefetch's own solver process failing to open the liver stops the background with
    its reason (prefetch_error); the window's grasps are still solved on request."""
    from surrogate.green_rows import GrownGreen
    from surrogate.manipulator import GraspManipulator
    from surrogate.over_green import OverGreen

    d, info, run = patient
    rest = load_predictor(run / "model")
    part, _, other = _near_copy(d, OverGreen(rest, d / "data", _placed(rest, d, info)),
                                tmp_path)
    opened = GrownGreen._open

    def second_fails(self, threads):
        if threads == 1:
            raise ValueError("no second process here")
        return opened(self, threads)

    monkeypatch.setattr(GrownGreen, "_open", second_fails)
    solver = str(Path(__file__).resolve().parents[2] / ".venv-solver" / "bin" / "python")
    m = GraspManipulator(part, solver=solver)
    try:
        m.prefetch()
        m._grow._thread.join(timeout=60)
        assert not m._grow.prefetching and m._grow.prefetch_seconds is None
        assert m._grow.prefetch_error == "no second process here"
        assert m.pick(m.points[other]) == other and len(m.solved_seconds) == 1
    finally:
        m.close()


def test_the_manipulators_timing_counts_grasps_during_and_after_the_background(patient,
                                                                               tmp_path):
    """surrogate.latency.timed_manipulator (bench/surgical_loads.py --ready): n grasps timed
    while the background solves, n after it ended (its seconds kept), a later call's median."""
    from surrogate.latency import timed_manipulator
    from surrogate.over_green import OverGreen

    d, info, run = patient
    rest = load_predictor(run / "model")
    part = _near_copy(d, OverGreen(rest, d / "data", _placed(rest, d, info)), tmp_path)[0]
    solver = str(Path(__file__).resolve().parents[2] / ".venv-solver" / "bin" / "python")
    t = timed_manipulator(part, solver, n=2, calls=3)
    assert len(t["during_ms"]) == len(t["after_ms"]) == 2 and t["open_s"] > 0
    assert t["prefetch_s"] > 0 and t["call_ms"] > 0


def test_the_manipulator_opens_on_a_model_over_the_livers_greens_function(patient, tmp_path):
    """python -m surrogate.viewer RUN --place LIVER --base DATA: the handles' forces answered
    as make liver answers them (OverGreen's field at every node of the liver's own mesh),
    the push mode a force's opposite, no input sliders; off screen it draws its frames."""
    from surrogate.evaluate import place
    from surrogate.over_green import OverGreen
    from surrogate.viewer import _parser, build, main

    d, info, run = patient
    argv = [str(run), "--place", info["liver"], "--base", str(d / "data")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = build(_parser().parse_args(argv))[0]
        over = OverGreen(load_predictor(run / "model"), d / "data",
                         place(load_predictor(run / "model"), info["liver"], None,
                               d / "placement.npz")[0])
    node = m.handles[0].node
    f = m.set_force([0.0, 0.0, -0.3])
    frame = m.predict()
    np.testing.assert_allclose(frame.u, over(f[None], [node]), atol=1e-6)
    assert frame.u.shape == (over.geometry.n_nodes, 3) and m.inputs == []
    np.testing.assert_allclose(frame.surface_u, frame.u[m.surface.nodes])
    m.toggle_mode()   # push: the sphere on the other side, the same force
    np.testing.assert_allclose(m.drag(m.handle_position()), f)
    with pytest.raises(ValueError, match="no material or shape input"):
        m.set_input(0, 1.0)
    assert main(argv + ["--offscreen", "--out", str(tmp_path / "v")]) == 0
    assert len(list((tmp_path / "v").glob("frame_*.png"))) > 10
