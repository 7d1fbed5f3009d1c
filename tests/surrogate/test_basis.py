"""The reduced-basis design (surrogate/basis.py): its modes, its training, its export and
reload through the one ``load_predictor`` call, and what it refuses."""

import json
import shutil

import numpy as np
import pytest

from surrogate import load_predictor
from surrogate.basis import (
    BasisDesignError,
    check_dataset,
    compute_modes,
    predict_samples,
    projection_mee,
)
from surrogate.config import get_config
from surrogate.data import load_dataset
from surrogate.train import fit_design, train_and_evaluate


@pytest.fixture(scope="module")
def ds(synth_dir):
    return load_dataset(synth_dir)


@pytest.fixture(scope="module")
def run(synth_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("basis_run")
    cfg = get_config("basis", folds=4, epochs=60, modes=24, hidden=[64, 64], batch_size=16)
    result = train_and_evaluate(synth_dir, out, cfg, log_fn=lambda m: None)
    return out, result


def test_randomised_modes_span_the_exact_ones():
    """A field matrix of rank 12 plus noise: the randomised range finder (used for long
    fields) finds the same leading subspace as the exact SVD."""
    rng = np.random.default_rng(0)
    U = rng.standard_normal((400, 12)) @ rng.standard_normal((12, 3300))
    U += 1e-6 * rng.standard_normal(U.shape)
    exact = np.linalg.svd(U, full_matrices=False)[2][:12]
    fast = compute_modes(np.vstack([U] * 8), 12)  # 3200 x 3300: the randomised path
    assert fast.shape == (12, 3300)
    np.testing.assert_allclose(fast @ fast.T, np.eye(12), atol=1e-10)
    # every exact mode lies in the span of the randomised ones
    assert np.abs(exact - exact @ fast.T @ fast).max() < 1e-6


def test_projection_error_falls_with_the_modes(ds):
    from surrogate.basis import fields

    U = fields(ds, np.arange(ds.n_samples))
    errs = [projection_mee(U, compute_modes(U, k)) for k in (2, 8, 32)]
    assert errs[0] > errs[1] > errs[2] >= 0, errs
    full = compute_modes(U, min(U.shape))
    assert projection_mee(U, full) < 1e-9


def test_basis_beats_naive_and_reports_like_the_nodewise_design(run):
    out, result = run
    assert result["skill"] < 0.5, result["skill"]
    meta = json.loads((out / "model" / "model.json").read_text())
    assert meta["design"] == "basis" and meta["version"] == 3
    assert (out / "model" / "basis.npz").stat().st_size > 0


def test_exported_basis_model_agrees_with_the_model_in_memory(ds, tmp_path):
    """Train in memory, export, reload through load_predictor: the same displacements (float32
    tolerance), for whole fields, node subsets and batches; no load gives no displacement."""
    from surrogate.export import export_model

    cfg = get_config("basis", epochs=40, modes=16, hidden=[32])
    model, _ = fit_design(ds, np.arange(ds.n_samples - 6), cfg, 0, "", lambda m: None)
    export_model(tmp_path / "m", model, cfg, ds)
    predict = load_predictor(tmp_path / "m")
    held = np.arange(ds.n_samples - 6, ds.n_samples)
    mine, _, _ = predict_samples(ds, model, held)
    mine = mine.reshape(held.size, -1, 3)
    theirs = predict(ds.forces[held], ds.load_nodes[held])
    scale = np.abs(mine).max()
    assert theirs.shape == mine.shape and scale > 0
    np.testing.assert_allclose(theirs, mine, rtol=1e-4, atol=1e-5 * scale)
    one = predict(ds.forces[held[2]], ds.load_nodes[held[2]], nodes=np.array([3, 0, 11]))
    np.testing.assert_allclose(one, mine[2][[3, 0, 11]], rtol=1e-4, atol=1e-5 * scale)
    assert np.abs(predict(np.zeros((1, 3)), [5])).max() == 0.0


def test_basis_model_refuses_what_it_cannot_do(run, tmp_path):
    out, _ = run
    predict = load_predictor(out / "model")
    pts = predict.points
    with pytest.raises(ValueError, match="geometry"):
        predict(np.array([[0.0, 0.0, -0.3]]), [4], geometry=(pts, predict.fixed, []))
    bad = tmp_path / "bad"
    shutil.copytree(out / "model", bad)
    with np.load(bad / "basis.npz") as z:
        modes = z["modes"].copy()
    modes[0, 0] = np.nan
    np.savez(bad / "basis.npz", modes=modes)
    with pytest.raises(ValueError, match="basis.npz"):
        load_predictor(bad)
    (bad / "basis.npz").unlink()
    with pytest.raises(ValueError, match="basis.npz: missing"):
        load_predictor(bad)


def test_basis_design_needs_one_liver(ds):
    import dataclasses

    two = dataclasses.replace(ds, points=ds.points * 2, fixed=ds.fixed * 2)
    with pytest.raises(BasisDesignError, match="one liver"):
        check_dataset(two)


@pytest.mark.parametrize("dtype, rel", [("bfloat16", 0.03), ("float16", 0.01)])
def test_reduced_precision_basis_is_close_to_float32(run, dtype, rel):
    out, _ = run
    f = np.array([[[0.0, 0.1, -0.3]], [[0.2, 0.0, 0.1]]])
    nodes = np.array([[4], [40]])
    full = load_predictor(out / "model")(f, nodes)
    low = load_predictor(out / "model", dtype=dtype)(f, nodes)
    assert low.dtype == np.float32
    assert np.abs(low - full).max() <= rel * np.abs(full).max()


def test_a_load_where_the_scene_never_loads_is_flagged_by_the_basis_too(run):
    pred = load_predictor(run[0] / "model")
    never = np.setdiff1d(pred.fixed, pred.loadable)[:1]
    assert never.size
    with pytest.warns(UserWarning, match="never loaded in training"):
        pred([[0.0, 0.0, -0.4]], never)


def test_input_noise_regularises_the_basis_in_training_only_and_dropout_is_refused(ds):
    """input_noise perturbs the basis network's normalised features in training steps (not in
    validation, not without it); dropout, which the basis network does not have, is refused
    instead of being ignored."""
    import jax

    from surrogate.basis import BasisProblem

    tr, va = np.arange(ds.n_samples - 4), np.arange(ds.n_samples - 4, ds.n_samples)
    noisy = BasisProblem(ds, tr, va, get_config("basis", modes=8, hidden=[16],
                                                input_noise=0.5), 0)
    plain = BasisProblem(ds, tr, va, get_config("basis", modes=8, hidden=[16]), 0)
    params = plain.init(jax.random.PRNGKey(0))
    idx, key = plain.batch(tr[:8]), jax.random.PRNGKey(1)
    clean = float(plain.loss(params, plain.data, idx, key, True))
    assert float(plain.loss(params, plain.data, idx, key, False)) == pytest.approx(clean,
                                                                                  rel=1e-6)
    assert float(noisy.loss(params, noisy.data, idx, key, False)) == pytest.approx(clean,
                                                                                  rel=1e-5)
    assert float(noisy.loss(params, noisy.data, idx, key, True)) != pytest.approx(clean,
                                                                                 rel=1e-3)
    for design in ("basis", "population_basis"):
        with pytest.raises(ValueError,
                           match=f"dropout: the {design} design does not take it, only nodewise"):
            get_config(design, dropout=0.1)
    for key, value in (("shape_inputs", 3), ("load_context", True)):
        for design in ("nodewise", "basis"):
            with pytest.raises(ValueError, match=f"{key}: the {design} design does not take it, "
                               "only population_basis"):
                get_config("small", design=design, **{key: value})
    with pytest.raises(ValueError, match="shape_inputs: expected 'all' or an integer >= 0"):
        get_config("population_basis", shape_inputs=-1)
    with pytest.raises(ValueError, match="load_context: expected true or false"):
        get_config("population_basis", load_context=1)


def test_an_ensemble_predicts_the_mean_of_its_members(ds, tmp_path):
    """ensemble = 3: three networks on the same modes; its first member is the single model
    (same seed and batches), the members differ, and the exported ensemble predicts the mean
    of its members' predictions (each member as a model of its own). A node-wise ensemble and
    a params file with another number of members are refused."""
    import dataclasses

    import jax

    from surrogate.export import export_model

    train = np.arange(ds.n_samples - 6)
    held = np.arange(ds.n_samples - 6, ds.n_samples)
    cfg = get_config("basis", epochs=15, modes=12, hidden=[24], ensemble=1)
    single, _ = fit_design(ds, train, cfg, 0, "", lambda m: None)
    ens, hist = fit_design(ds, train, {**cfg, "ensemble": 3}, 0, "", lambda m: None)
    assert ens.members == 3 and sorted({h["member"] for h in hist}) == [0, 1, 2]
    member = [dataclasses.replace(ens, members=1,
                                  params=jax.tree_util.tree_map(lambda a, m=m: a[m],
                                                                ens.params))
              for m in range(3)]
    each = [predict_samples(ds, m, held)[0] for m in member]
    first, _, _ = predict_samples(ds, single, held)
    scale = np.abs(first).max()
    np.testing.assert_allclose(each[0], first, rtol=1e-4, atol=1e-5 * scale)
    assert np.abs(each[1] - each[0]).max() > 1e-3 * scale  # other initialisations
    mean, _, _ = predict_samples(ds, ens, held)
    np.testing.assert_allclose(mean, np.mean(each, axis=0), rtol=1e-4, atol=1e-5 * scale)
    export_model(tmp_path / "e", ens, {**cfg, "ensemble": 3}, ds)
    got = load_predictor(tmp_path / "e")(ds.forces[held], ds.load_nodes[held])
    np.testing.assert_allclose(got.reshape(-1, 3), mean, rtol=1e-4, atol=1e-5 * scale)
    meta = json.loads((tmp_path / "e" / "model.json").read_text())
    meta["stats"]["members"] = 2
    (tmp_path / "e" / "model.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="params.npz: 'hidden_0/kernel' has shape"):
        load_predictor(tmp_path / "e")
    with pytest.raises(ValueError, match="ensemble: the nodewise design does not take it, "
                       "only basis and population_basis"):
        get_config("small", ensemble=2)


@pytest.fixture(scope="module")
def two_loads(tmp_path_factory):
    """A synthetic two-force dataset: the tiny scene with two loads, each case's field the sum
    of a bump around each load node along its force."""
    from tests.fixtures import TEST_SCENE, synthetic_dataset

    d = tmp_path_factory.mktemp("two_loads")
    scene = d / "two_loads.toml"
    scene.write_text(TEST_SCENE.read_text().replace("count = 1", "count = 2"))
    return load_dataset(synthetic_dataset(d / "data", n_sims=30, n=5, n_steps=2,
                                          scene_file=scene))


def test_shared_loads_predict_the_same_field_whichever_load_is_listed_first(two_loads,
                                                                          tmp_path):
    """shared_loads: one network reads both loads, so swapping the two loads of a case
    (nodes and forces) leaves the exported model's field unchanged, while the network with
    one block per load (shared_loads = false) changes it. The loads share their feature
    statistics, and the exported model agrees with the model in memory."""
    from surrogate.export import export_model

    ds = two_loads
    assert ds.spec.n_loads == 2
    train = np.arange(ds.n_samples - 8)
    held = np.arange(ds.n_samples - 8, ds.n_samples)
    swap = np.array([1, 0])
    swapped = {}
    for shared in (True, False):
        cfg = get_config("basis", epochs=20, modes=12, hidden=[24], shared_loads=shared)
        model, _ = fit_design(ds, train, cfg, 0, "", lambda m: None)
        out = tmp_path / str(shared)
        export_model(out, model, cfg, ds)
        predict = load_predictor(out)
        mine = predict_samples(ds, model, held)[0].reshape(held.size, -1, 3)
        got = predict(ds.forces[held], ds.load_nodes[held])
        scale = np.abs(mine).max()
        assert scale > 0
        np.testing.assert_allclose(got, mine, rtol=1e-4, atol=1e-5 * scale)
        swapped[shared] = np.abs(predict(ds.forces[held][:, swap],
                                         ds.load_nodes[held][:, swap]) - got).max() / scale
        stats = json.loads((out / "model.json").read_text())["stats"]
        assert stats["shared_loads"] is shared
        per = np.array(stats["x_mean"][:14]).reshape(2, 7)
        assert np.allclose(per[0], per[1]) == shared  # the loads' statistics: pooled or not
    assert swapped[True] < 1e-5, swapped
    assert swapped[False] > 1e-3, swapped


def test_with_one_load_the_shared_network_is_the_network_per_load():
    """One load: shared_loads builds the same layers and, from the same parameters, the same
    coefficients (so the one-load scenes' models are unchanged by the key)."""
    import jax

    from surrogate.basis import network

    rng = np.random.default_rng(0)
    x, f = rng.normal(size=(5, 9)).astype(np.float32), rng.normal(size=(5, 1, 3))
    f = f.astype(np.float32)
    joint, shared = network([16, 8], 6, 1), network([16, 8], 6, 1, shared=True)
    params = joint.init(jax.random.PRNGKey(0), x, f)["params"]
    shapes = jax.tree_util.tree_map(np.shape, params)
    assert jax.tree_util.tree_map(np.shape, shared.init(jax.random.PRNGKey(0), x, f)[
        "params"]) == shapes
    np.testing.assert_allclose(shared.apply({"params": params}, x, f),
                               joint.apply({"params": params}, x, f), rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="shared_loads: the nodewise design does not take "
                       "it, only basis and population_basis"):
        get_config("small", shared_loads=True)


def test_each_loss_is_what_it_says_on_the_decoded_fields(ds):
    """loss = mse: the mean over fields of the squared coefficient error (the squared field
    error in the modes' span); rms: the mean of its square roots; mee: the mean Euclidean node
    error of the decoded error field times sqrt(nodes). Each recomputed here in numpy from the
    network's coefficients and the modes; an unknown loss is refused."""
    import jax

    from surrogate.basis import BasisProblem

    tr, va = np.arange(ds.n_samples - 4), np.arange(ds.n_samples - 4, ds.n_samples)
    probs = {k: BasisProblem(ds, tr, va, get_config("basis", modes=8, hidden=[16], loss=k), 0)
             for k in ("mse", "rms", "mee")}
    p = probs["mse"]
    params = p.init(jax.random.PRNGKey(0))
    idx, key = p.batch(tr[:8]), jax.random.PRNGKey(1)
    pred = np.asarray(p.net.apply({"params": params}, p.data["x"][idx], p.data["f"][idx]),
                      dtype=np.float64)
    err = pred - np.asarray(p.data["target"][idx], dtype=np.float64)
    sq = (err ** 2).sum(axis=1)
    node = (err @ p.modes.astype(np.float64)).reshape(len(err), -1, 3)
    expected = {"mse": sq.mean(), "rms": np.sqrt(sq).mean(),
                "mee": np.linalg.norm(node, axis=2).mean() * np.sqrt(node.shape[1])}
    for k, prob in probs.items():
        assert float(prob.loss(params, prob.data, idx, key, False)) == pytest.approx(
            expected[k], rel=1e-4), k
    # the three differ on this batch (the test tells them apart)
    assert len({round(v, 6) for v in expected.values()}) == 3
    with pytest.raises(ValueError, match="loss: expected 'mse', 'rms' or 'mee'"):
        get_config("basis", loss="mae")
    with pytest.raises(ValueError, match="loss: the nodewise design does not take it"):
        get_config("small", loss="rms")
