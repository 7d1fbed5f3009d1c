"""A patient's model of grasps (surrogate.patient.grasps): its force law and field correction
kept only where they beat the population model on held-out simulations, written and read
back; make patient LOAD=grasp end to end on a real liver with the shipped model of grasps."""

import json
import shutil

import numpy as np
import pytest

from surrogate.grasp import GraspForce
from surrogate.patient.grasps import (
    GraspCases,
    PatientGrasp,
    answered,
    fit_patient_grasp,
    held_out,
)


def _cases(rng, law: GraspForce, residual: float = 0.0, sims: int = 8, n_out: int = 30):
    """One-tool grasps: ``sims`` simulations of 8 steps to 40 mm at random centres within
    10 mm of a site and random directions; the population model's force is the base's
    stiffened by exp(0.02 p), the FE's by ``law`` (x 1 +- 2 % noise); the FE field is the
    model's plus ``residual`` x (p / 40)^2 x a fixed pattern (a residual quadratic in the
    pull, the same shape everywhere).
    """
    pattern = rng.normal(size=(n_out, 3))
    rows = {k: [] for k in ("sims", "centres", "pulls", "model", "truth", "base_force",
                            "model_force", "fe_force")}
    for s in range(sims):
        x, e = rng.uniform(40, 60, 3), rng.normal(size=3)   # around a site
        e /= np.linalg.norm(e)
        k_lin = rng.uniform(0.02, 0.06)
        for p in np.arange(1, 9) * 5.0:
            d, base = p * e, rng.normal(size=(n_out, 3)) * p / 40
            f_lin = k_lin * p * e
            for key, v in (("sims", s), ("centres", x), ("pulls", d), ("model", base),
                           ("truth", base + residual * (p / 40) ** 2 * pattern),
                           ("base_force", f_lin), ("model_force", f_lin * np.exp(0.02 * p)),
                           ("fe_force", law(d, f_lin) * (1 + 0.02 * rng.normal()))):
                rows[key].append(v)
    return GraspCases(**{k: np.asarray(v, np.float64) for k, v in rows.items()})


def test_a_patients_force_correction_is_kept_where_it_beats_the_populations():
    """A patient stiffer than the population (exp(0.045 p) against exp(0.02 p)): the force's
    correction is kept and its error on new grasps at 40 mm is under a fifth of the
    population's; a patient the population's law describes (2 % noise) keeps none; one
    simulation is nothing to check a correction on."""
    rng = np.random.default_rng(0)
    stiff = GraspForce(0.045, 0.0)
    pg, info = fit_patient_grasp(_cases(rng, stiff, sims=10))
    assert pg.force is not None and info["force"]["cv_error_n"] > 0
    m = held_out(pg, _cases(rng, stiff, sims=4))
    assert m["patient"]["large_force_error_pct"] < 0.2 * m["population"]["large_force_error_pct"]
    pg, info = fit_patient_grasp(_cases(rng, GraspForce(0.02, 0.0), sims=10))
    assert pg.force is None and info["force"] is None
    assert fit_patient_grasp(_cases(rng, stiff, sims=1))[0].force is None


def test_a_patients_field_correction_learns_its_residual_and_reads_back(tmp_path):
    """A residual of 2 mm at 40 mm growing as the pull squared: the correction is kept and
    removes most of it on new grasps; nothing is added on the patch (several tools get
    nothing); written and read back it answers the same to 1e-12; a model with nothing kept
    answers as the population's."""
    rng = np.random.default_rng(1)
    c = _cases(rng, GraspForce(0.02, 0.0), residual=2.0, sims=10)
    pg, info = fit_patient_grasp(c)
    assert pg.field is not None and info["field"]["cv_mee_mm"] < 0.5
    new = _cases(np.random.default_rng(1), GraspForce(0.02, 0.0), residual=2.0, sims=10)
    m = held_out(pg, new.take(new.sims >= 7))
    assert m["patient"]["large_mee_mm"] < 0.3 * m["population"]["large_mee_mm"]
    pg.save(tmp_path)
    back = PatientGrasp.load(tmp_path)
    u, f = answered(pg, new)
    u2, f2 = answered(back, new)
    np.testing.assert_allclose(u2, u, atol=1e-12)
    np.testing.assert_allclose(f2, f, atol=1e-12)
    assert not pg.field_added(c.centres[0], np.ones((2, 3)), c.model[0]).any()
    # a grasp beyond 20 mm of every grasp it was fitted on: none, and said so
    far, d = np.array([300.0, 300.0, 300.0]), np.array([[0.0, 0.0, 40.0]])
    assert not pg.field_added(far, d, c.model[0]).any() and pg.distance(far) > 300
    assert "from the patient's grasps (beyond 20 mm)" in pg.beyond(far[None])
    near = c.centres[0] + [0.0, 0.0, 5.0]
    assert pg.beyond(near[None]) == "" and pg.field_added(near, d, c.model[0]).any()
    assert "2 tools" in pg.beyond(np.stack([near, near]))
    none = PatientGrasp(None, None)
    u0, f0 = answered(none, new)
    assert np.array_equal(u0, new.model) and np.array_equal(f0, new.model_force)
    with pytest.raises(ValueError, match="missing: not a patient's model of grasps"):
        PatientGrasp.load(tmp_path / "nowhere")


def test_truth_scene_draws_the_grasps_around_a_site_on_the_liver(tmp_path, capsys):
    """truth-scene --near writes the site into the scene's [loads]; a site 30 mm off the
    liver file's surface beyond a 20 mm reach is refused, naming the flag and the gap."""
    import tomllib

    from surrogate.__main__ import main
    from tests.surrogate.conftest import ROOT

    liver = ROOT.parent / "shared" / "data" / "livers" / "real" / "Amos-054.obj"
    scene = ROOT / "data_spec" / "scenes" / "scene4_grasp.toml"
    from surrogate.predict_liver import read_liver_surface

    v = read_liver_surface(liver)[0]
    top = v[np.argmax(v[:, 2])]
    common = ["truth-scene", str(ROOT / "models" / "scene4_grasp"), str(liver), "--scene",
              str(scene), "--sims", "3"]
    out = tmp_path / "scene.toml"
    assert main([*common, "--out", str(out), "--near", *map(str, top)]) == 0
    loads = tomllib.loads(out.read_text())["loads"]
    np.testing.assert_allclose(loads["near"], top, atol=1e-3)
    assert loads["kind"] == "grasp" and "near_radius" not in loads
    off = top + [0.0, 0.0, 30.0]
    assert main([*common, "--out", str(tmp_path / "no.toml"), "--near", *map(str, off)]) == 2
    err = capsys.readouterr().err
    assert "--near" in err and "30.0 mm away, beyond the reach of 20 mm" in err
    assert not (tmp_path / "no.toml").exists()
    # bench/patient_grasps.py's site: a vertex 50 mm or more from the placed fixed region,
    # the same one each time (drawn from the name), within the file's surface
    from data_spec.eligible_loads import min_distance
    from surrogate.evaluate import place
    from surrogate.patient.grasps import grasp_site
    from surrogate.predictor import load_predictor

    pred = load_predictor(ROOT / "models" / "scene4_grasp" / "model", load="grasp")
    site = grasp_site(pred, liver)
    assert site == grasp_site(pred, liver)
    pl = place(pred, liver, None)[0]
    fixed = pl.to_liver(pl.points[pred.shape_model.fixed_nodes])
    assert min_distance(np.array([site]), fixed)[0] >= 50.0
    assert min_distance(np.array([site]), v)[0] < 0.01


def test_the_corrections_against_k_are_measured_on_the_same_held_out_grasps():
    """against_k: each K fitted on the first K simulations only, every K measured on the
    same last ones (the population model's errors equal in every row), the patient's error
    at 40 mm falling as K grows on a residual it can learn."""
    from surrogate.patient.grasps import against_k

    c = _cases(np.random.default_rng(2), GraspForce(0.045, 0.0), residual=2.0, sims=14)
    rows = against_k(c, [2, 4, 8], held=6)
    assert [r["k"] for r in rows] == [2, 4, 8] and rows[0]["simulations"] == 6
    assert all(r["population"] == rows[0]["population"] for r in rows)
    big = [r["patient"]["large_mee_mm"] for r in rows]
    assert big[-1] < 0.5 * rows[0]["population"]["large_mee_mm"] and big[-1] <= big[0]


@pytest.mark.dataset
def test_a_patients_grasp_data_holds_its_small_strain_base():
    """make patient LOAD=grasp's one-liver grasp scene on Amos-054: its small-strain base
    (fem_sim linear --green) holds each patch at its tool's pull and is within 0.5 mm of the
    FE at the first 5 mm step (a third of the naive model's error at most)."""
    from data_spec.linear_fields import read_dataset_linear
    from surrogate.data import load_dataset
    from tests.surrogate.conftest import generated_dataset

    d = generated_dataset("LIVERFEM_TEST_PATIENT_GRASP")
    ds, lf = load_dataset(d / "data"), read_dataset_linear(d / "data")
    assert lf.tool_force is not None and lf.green is not None
    for row, sim in enumerate(lf.case_index):
        s = np.flatnonzero(ds.sample_sim == sim)
        if not s.size:
            continue
        over_patch = lf.displacement[row][np.isin(lf.output_nodes, _patch(ds, s[0]))]
        np.testing.assert_allclose(over_patch, np.broadcast_to(
            ds.forces[s[-1], 0] / ds.sample_fraction[s[-1]], over_patch.shape), atol=1e-3)
        first = ds.targets[ds.sample_offset[s[0]]:ds.sample_offset[s[0] + 1]]
        mee = np.linalg.norm(first - ds.sample_fraction[s[0]] * lf.displacement[row],
                             axis=1).mean()
        naive = np.linalg.norm(first - first.mean(axis=0), axis=1).mean()
        assert mee < 0.5 and mee < naive / 3, (sim, mee, naive)


@pytest.mark.dataset
def test_make_patient_grasps_a_real_liver_end_to_end(tmp_path):
    """make patient LOAD=grasp on Amos-054 with the shipped model of grasps: the adaptation
    says what it kept and measures it on the held-out grasps, the field better at 40 mm;
    predict-liver --patient and the manipulator's --patient answer a held-out grasp with the
    patient's corrections, as the model corrected in process does; --patient without a
    grasp is refused."""
    import warnings

    from surrogate.__main__ import main
    from surrogate.data import load_dataset
    from surrogate.evaluate import place
    from surrogate.over_green import OverGreen
    from surrogate.predictor import load_predictor
    from surrogate.viewer import _parser, build
    from tests.surrogate.conftest import ROOT, generated_dataset

    d = generated_dataset("LIVERFEM_TEST_PATIENT_GRASP")
    info = json.loads((d / "run" / "adaptation.json").read_text())
    assert info["load"] == "grasp" and len(info["fe_simulations"]) == 8
    # eight grasps around the site correct the field, which beats the population model's
    # on the three held out at their largest pulls (docs/patient_grasps.md: by a fifth)
    m = info["held_out"]
    assert m["simulations"] == 3 and info["field"] is not None
    assert m["patient"]["large_mee_mm"] < m["population"]["large_mee_mm"]
    ds, liver, model = load_dataset(d / "data"), info["liver"], ROOT / "models" / "scene4_grasp"
    held = np.flatnonzero(ds.sample_sim == info["held_out_simulations"][0])[-1]
    at, pull = ds.load_points[held, 0], ds.forces[held, 0]
    args = ["predict-liver", str(model), liver, "--base", str(d / "data"), "--grasp",
            *map(str, at), *map(str, pull), "--out", str(tmp_path), "--no-picture",
            "--placement", str(d / "placement.npz")]
    assert main([*args, "--patient", str(d / "run")]) == 0
    out = json.loads((tmp_path / "prediction.json").read_text())
    pred = load_predictor(model / "model", load="grasp")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        placement = place(pred, liver, None, d / "placement.npz")[0]
        tool = build(_parser().parse_args([str(model), "--place", liver, "--base",
                                           str(d / "data"), "--grasp", "--patient",
                                           str(d / "run")]))[0]
    over = OverGreen(pred, d / "data", placement, patient=PatientGrasp.load(d / "run"))
    u, force = over.grasp(at[None])(pull[None])
    np.testing.assert_allclose(out["forces_N"], force, rtol=1e-5)
    tool.pick(at)   # the manipulator's grasping tool: the same field and force
    tool.set_force(pull)
    np.testing.assert_allclose(tool.predict().u, u, atol=1e-5)
    np.testing.assert_allclose(tool.handles[0].force, force[0], rtol=1e-5)
    assert main(["predict-liver", str(model), liver, "--base", str(d / "data"), "--force",
                 *map(str, at), "0", "0", "1", "--patient", str(d / "run")]) == 2
    # far from the site the patient's grasps were drawn around: the population model's
    # answer, with a warning that says so
    free = over.free_nodes[np.argmax(np.linalg.norm(over.points[over.free_nodes] - at, axis=1))]
    with pytest.warns(UserWarning, match="from the patient's grasps"):
        far = over.grasp(over.points[[free]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = OverGreen(pred, d / "data", placement).grasp(over.points[[free]])
    np.testing.assert_allclose(far(pull[None])[0], plain(pull[None])[0], atol=1e-9)
    np.testing.assert_allclose(far.force(pull[None]), plain.force(pull[None]), atol=1e-12)


def _patient_liver():
    """make test's patient of grasps (Amos-054): its directory, dataset, the shipped model's
    folder and predictor, its placement, and the sample of the first held-out grasp at its
    largest pull."""
    import warnings

    from surrogate.data import load_dataset
    from surrogate.evaluate import place
    from surrogate.predictor import load_predictor
    from tests.surrogate.conftest import ROOT, generated_dataset

    d = generated_dataset("LIVERFEM_TEST_PATIENT_GRASP")
    info = json.loads((d / "run" / "adaptation.json").read_text())
    ds, model = load_dataset(d / "data"), ROOT / "models" / "scene4_grasp"
    held = np.flatnonzero(ds.sample_sim == info["held_out_simulations"][0])[-1]
    pred = load_predictor(model / "model", load="grasp")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        placement = place(pred, info["liver"], None, d / "placement.npz")[0]
    return d, ds, model, pred, placement, held


@pytest.mark.dataset
def test_a_patients_corrections_are_refused_on_another_model_and_a_force_is_held(tmp_path):
    """The corrections are residuals of the shipped model's answers: the same model with its
    force law changed refuses them, naming what to run. A force held by the tool: the
    held-out grasp's FE reaction at its largest pull given to the population model, whose
    pull and field are nearer the FE's than the small-strain inverse's (K^-1 F); with the
    patient's corrections it is refused (they are not inverted)."""
    from surrogate.metrics import mee
    from surrogate.over_green import OverGreen
    from surrogate.patient.grasps import PatientGrasp
    from surrogate.predictor import load_predictor

    d, ds, model, pred, placement, held = _patient_liver()
    at, pull = ds.load_points[held, 0], ds.forces[held, 0]
    other = tmp_path / "other"
    shutil.copytree(model / "model", other)
    (other / "fingerprint.json").unlink()
    meta = json.loads((other / "model.json").read_text())
    meta["grasp_force"]["a"] *= 1.01
    (other / "model.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="fitted on another population model"):
        OverGreen(load_predictor(other, load="grasp"), d / "data", placement,
                  patient=PatientGrasp.load(d / "run"))
    grasp = OverGreen(pred, d / "data", placement).grasp(at[None])
    fe = ds.reactions[held]
    truth = ds.targets[ds.sample_offset[held]:ds.sample_offset[held + 1]]
    pulled, linear = grasp.pull_for(fe), np.linalg.solve(grasp.stiffness, fe[0])[None]
    np.testing.assert_allclose(grasp.force(pulled), fe, atol=1e-9)
    assert np.linalg.norm(pulled - pull) < 0.5 * np.linalg.norm(linear - pull)
    assert mee(grasp(pulled)[0], truth) < mee(grasp.base(linear)[0], truth)
    over = OverGreen(pred, d / "data", placement, patient=PatientGrasp.load(d / "run"))
    with pytest.raises(ValueError, match="patient's corrections"):
        over.grasp(at[None]).pull_for(fe)


def _patch(ds, s: int) -> np.ndarray:
    """The mesh nodes sample ``s``'s tool holds (the solver's rule, its 10 mm radius)."""
    from data_spec import read_geometry
    from data_spec.eligible_loads import grasp_patch
    from data_spec.shards import geometry_path

    g = read_geometry(geometry_path(ds.directory, ds.geo_ids[0]))
    return grasp_patch(g.points, g.surface_nodes, int(ds.load_nodes[s, 0]), 10.0)
