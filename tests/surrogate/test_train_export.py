"""Training beats the naive model on held-out simulations; the exported model reloads in a fresh
process and predicts bitwise identically; the predictor rejects bad input."""

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

from surrogate import load_predictor
from surrogate.config import get_config
from surrogate.train import train_and_evaluate


@pytest.fixture(scope="module")
def run(synth_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    cfg = get_config("small", folds=4, epochs=30, hidden=[64, 64], batch_size=512,
                     early_stopping=8)
    result = train_and_evaluate(synth_dir, out, cfg, log_fn=lambda m: None)
    return out, result


def test_beats_naive_on_held_out_simulations(run):
    out, result = run
    assert result["skill"] < 0.5, result["skill"]
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["skill"] == pytest.approx(result["skill"])
    for name in ("errors_boxplot.png", "actual_vs_predicted.png", "metrics.md", "config.json"):
        assert (out / name).stat().st_size > 0


def test_export_reloads_bitwise_in_a_fresh_process(run, tmp_path):
    """Same inputs, same shapes, same machine: a fresh process gives the same bits. A
    prediction of another shape (a subset of nodes, one case) may use other XLA kernels, so
    it is compared with a float32 tolerance."""
    out, _ = run
    predict = load_predictor(out / "model")
    forces = np.array([[[0.1, -0.2, 0.3]], [[0.0, 0.0, -0.4]]])
    nodes = np.array([[5], [17]])
    here = predict(forces, nodes)
    np.save(tmp_path / "inp.npy", forces)
    code = (
        "import numpy as np, sys; from surrogate import load_predictor;"
        f"p = load_predictor({str(out / 'model')!r});"
        f"f = np.load({str(tmp_path / 'inp.npy')!r});"
        f"np.save({str(tmp_path / 'out.npy')!r}, p(f, np.array([[5], [17]])))")
    subprocess.run([sys.executable, "-c", code], check=True)
    there = np.load(tmp_path / "out.npy")
    assert here.dtype == np.float32 and here.shape == (2, 216, 3)
    assert np.array_equal(here, there)
    single = predict(forces[1], nodes[1], nodes=np.array([0, 7, 9]))
    scale = np.abs(here).max()
    np.testing.assert_allclose(single, here[1][[0, 7, 9]], rtol=1e-5, atol=1e-6 * scale)


def test_predictor_rejects_bad_input(run):
    predict = load_predictor(run[0] / "model")
    with pytest.raises(ValueError, match="forces: expected shape"):
        predict(np.zeros((2, 3)), [1, 2])
    with pytest.raises(ValueError, match="NaN"):
        predict([[np.nan, 0, 0]], [1])
    with pytest.raises(ValueError, match="load_nodes: expected integer node ids"):
        predict([[0, 0, 0.1]], [9999])
    with pytest.raises(ValueError, match="nodes: expected"):
        predict([[0, 0, 0.1]], [3], nodes=[-1])
    with pytest.raises(ValueError, match=r"load_nodes: expected shape \(4, 1\) for forces of "
                                         r"shape \(4, 1, 3\), got \(3, 1\)"):
        predict(np.zeros((4, 1, 3)), np.zeros((3, 1), int))
    with pytest.raises(ValueError, match="forces: no case given"):
        predict(np.zeros((0, 1, 3)), np.zeros((0, 1), int))
    with pytest.raises(ValueError, match="material: this model was trained on one material"):
        predict([[0, 0, 0.1]], [3], material=[4e-3, 10.0, 0.4])
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        predict([[0, 0, 4.0]], [3])
    assert any("exceeds the training range" in str(x.message) for x in w)


@pytest.mark.parametrize("dtype, rel", [("bfloat16", 0.05), ("float16", 0.01)])
def test_reduced_precision_predictor_is_close_to_float32(run, dtype, rel):
    """16-bit weights and activations: bfloat16 keeps 8 significand bits (relative rounding
    2^-9 ~ 2e-3 per operation), float16 11 bits (2^-12 ~ 2.4e-4); through three layers the
    prediction must stay within a few of those of the float32 one, relative to max |u|, and
    never bit-equal to it (else the cast did not happen)."""
    predict32 = load_predictor(run[0] / "model")
    predict16 = load_predictor(run[0] / "model", dtype=dtype)
    forces = np.array([[[0.1, -0.2, 0.3]], [[0.0, 0.0, -0.4]]])
    nodes = np.array([[5], [17]])
    a, b = predict32(forces, nodes), predict16(forces, nodes)
    assert b.dtype == np.float32 and np.all(np.isfinite(b))
    scale = np.abs(a).max()
    assert np.abs(a - b).max() < rel * scale
    assert not np.array_equal(a, b)
    with pytest.raises(ValueError, match="dtype: expected one of"):
        load_predictor(run[0] / "model", dtype="int8")


def test_node_subsets_follow_each_request(run):
    """The predictor keeps the last node set's features; every new set (another length,
    another integer type with the same bytes, back to an earlier one) gives its own rows."""
    predict = load_predictor(run[0] / "model")
    f, n = np.array([[0.1, 0.0, -0.3]]), np.array([11])
    full = predict(f, n)
    scale = np.abs(full).max()
    for sel in ([0, 7, 9], [3, 4], np.array([1, 0], np.int32), np.array([1], np.int64),
                [0, 7, 9]):
        got = predict(f, n, nodes=sel)
        np.testing.assert_allclose(got, full[np.asarray(sel)], rtol=1e-5, atol=1e-6 * scale)


def test_model_files_are_plain(run):
    d = run[0] / "model"
    meta = json.loads((d / "model.json").read_text())
    with np.load(d / "params.npz", allow_pickle=False) as z:
        assert all(z[k].dtype == np.float32 for k in z.files)
        n = len(meta["config"]["hidden"])
        assert sorted(z.files) == sorted([f"hidden_{i}/{w}" for i in range(n)
                                          for w in ("kernel", "bias")]
                                         + ["output/kernel", "output/bias"])
    assert meta["format"] == "liverfem-surrogate" and meta["version"] == 3
    assert meta["design"] == "nodewise"


def test_version_1_models_still_load_as_nodewise(run, tmp_path):
    """Models exported before the design was recorded (version 1, no "design") load and
    predict as node-wise models; an unknown design or version is refused by name."""
    import shutil

    d = tmp_path / "v1"
    shutil.copytree(run[0] / "model", d)
    meta = json.loads((d / "model.json").read_text())
    meta.pop("design")
    meta["version"] = 1
    # before version 3 the layers had flax's automatic names Dense_0, Dense_1, ...
    n = len(meta["config"]["hidden"])
    old = {f"hidden_{i}": f"Dense_{i}" for i in range(n)} | {"output": f"Dense_{n}"}
    with np.load(d / "params.npz") as z:
        arrays = {f"{old[k.split('/')[0]]}/{k.split('/')[1]}": z[k] for k in z.files}
    np.savez(d / "params.npz", **arrays)
    (d / "model.json").write_text(json.dumps(meta))
    f = np.array([[0.0, 0.1, -0.3]])
    np.testing.assert_allclose(load_predictor(d)(f, [3]), load_predictor(run[0] / "model")(f, [3]),
                               rtol=1e-6, atol=1e-7)
    for key, value, message in (("design", "graph", "design 'graph'"),
                                ("version", 4, "version 4")):
        (d / "model.json").write_text(json.dumps({**meta, key: value}))
        with pytest.raises(ValueError, match=message):
            load_predictor(d)


def test_predictor_on_an_explicit_geometry_matches_the_embedded_one(run):
    predict = load_predictor(run[0] / "model")
    f, n = np.array([[0.1, 0.0, -0.3]]), np.array([11])
    same = predict(f, n, geometry=(predict.points, predict.fixed, None))
    ref = predict(f, n)
    np.testing.assert_allclose(same, ref, rtol=1e-5, atol=1e-6 * np.abs(ref).max())
    with pytest.raises(ValueError, match="geometry: fixed_nodes"):
        predict(f, n, geometry=(predict.points, np.array([10**6]), None))


def test_material_model_warns_outside_the_training_range(tmp_path):
    """A model trained on varying materials takes (c, m, K) per case and warns when a material
    leaves the range it was trained on (by more than 5 %)."""
    import dataclasses

    from data_spec import OgdenMaterial, geometry_path, write_geometry, write_shard
    from tests.fixtures import box_mesh, synthetic_shard
    from tests.surrogate.conftest import ROOT

    geo = box_mesh(3)
    write_geometry(geometry_path(tmp_path, geo.geometry_id), geo)
    rng = np.random.default_rng(0)
    for i in range(12):
        c, m = rng.uniform(2e-3, 8e-3), rng.uniform(6.0, 14.0)
        shard = synthetic_shard(geo, i)
        shard = dataclasses.replace(shard, material=OgdenMaterial(c=[c], m=[m], K=100 * c),
                                    displacement=shard.displacement * 4.1e-3 / c)
        write_shard(tmp_path, shard)
    scene = (ROOT / "data_spec" / "scenes" / "scene3_materials.toml").read_text()
    (tmp_path / "scene.toml").write_text(scene.replace("n_simulations = 3000",
                                                      "n_simulations = 12"))
    cfg = get_config("small", folds=2, epochs=2, hidden=[16], batch_size=256,
                     final_fit=True)
    train_and_evaluate(tmp_path, tmp_path / "run", cfg, log_fn=lambda m: None)
    predict = load_predictor(tmp_path / "run" / "model")
    with pytest.raises(ValueError, match="material: this model needs"):
        predict([[0, 0, 0.4]], [3])
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        predict([[0, 0, 0.4]], [3], material=[5e-3, 10.0, 0.5])
    assert not any("outside the training range" in str(x.message) for x in w)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        predict([[0, 0, 0.4]], [3], material=[2e-2, 10.0, 2.0])
    assert any("outside the training range" in str(x.message) for x in w)


def test_streaming_from_disk_gives_the_same_training(synth_dir, tmp_path):
    """stream=True keeps the targets in a memory-mapped file (written shard by shard) and
    trains to bitwise the same metrics as the in-memory dataset; the file is removed after."""
    from surrogate.data import load_dataset

    mem = load_dataset(synth_dir, stream=False)
    disk = load_dataset(synth_dir, stream=True, spill_dir=tmp_path / "spill")
    assert isinstance(disk.targets, np.memmap) and not isinstance(mem.targets, np.memmap)
    np.testing.assert_array_equal(np.asarray(disk.targets), mem.targets)
    cfg = get_config("small", folds=2, epochs=2, hidden=[16], batch_size=256,
                     final_fit=False)
    results = {}
    for stream in (False, True):
        out = tmp_path / f"run_{stream}"
        results[stream] = train_and_evaluate(synth_dir, out, {**cfg, "stream": stream},
                                             log_fn=lambda m: None)
        assert not (out / "targets.f32").exists()
    assert results[True]["network"] == results[False]["network"]


def test_streaming_leaves_nothing_behind_when_a_shard_is_unreadable(synth_dir, tmp_path):
    """The spill file goes through data_spec's atomic_path: a shard that cannot be read
    half-way stops loading and leaves neither targets.f32 nor a temporary."""
    import shutil

    from data_spec import list_shards
    from surrogate.data import load_dataset

    d = tmp_path / "data"
    shutil.copytree(synth_dir, d)
    victim = list_shards(d)[-1]
    victim.write_bytes(victim.read_bytes()[:300])  # truncated
    spill = tmp_path / "spill"
    with pytest.raises(Exception):  # noqa: B017 (h5py's error type depends on the damage)
        load_dataset(d, stream=True, spill_dir=spill)
    assert list(spill.iterdir()) == []


@pytest.mark.parametrize("key, value, message", [
    ("y_std", [-1e30, 1.0, 1.0], r"stats\.y_std: scales must be > 0"),
    ("x_std", None, r"stats\.x_std: expected \d+ values"),
    ("x_mean", "nan", r"stats\.x_mean: contains NaN"),
    ("y_mean", "missing", r"stats\.y_mean: missing"),
])
def test_tampered_normalisation_statistics_are_refused_at_load(run, tmp_path, key, value,
                                                               message):
    """The normaliser is checked when a model is loaded, with the file and the key named:
    a model with a negative scale, a wrong size, a NaN or a missing entry never predicts."""
    import shutil

    d = tmp_path / "model"
    shutil.copytree(run[0] / "model", d)
    meta = json.loads((d / "model.json").read_text())
    stats = meta["stats"]
    if value == "nan":
        stats[key][0] = float("nan")
    elif value == "missing":
        del stats[key]
    elif value is None:
        stats[key] = stats[key][:-1]
    else:
        stats[key] = value
    (d / "model.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=message) as err:
        load_predictor(d)
    assert str(d / "model.json") in str(err.value)


def test_predictor_is_finite_at_the_corners_and_flags_inputs_outside_its_range(tmp_path):
    """A model whose scene varies material and geometry (an exported model built directly):
    finite predictions at every corner of the training ranges of force, material and shape
    coefficients, no warning there; a warning for each kind of input outside the range."""
    from types import SimpleNamespace

    import jax

    from surrogate.export import export_model
    from surrogate.features import FeatureSpec
    from surrogate.model import NodeMLP
    from surrogate.normalise import Normaliser

    spec = FeatureSpec(n_loads=1, material_dim=3, geometry_dim=2)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-50, 50, size=(40, 3))
    extra = np.array([[2e-3, 6.0, 0.2, -1.0, 0.0], [8e-3, 14.0, 0.8, 1.0, 2.0]])
    params = NodeMLP(hidden=(16,)).init(jax.random.PRNGKey(0), np.zeros((1, spec.dim)))
    norm = Normaliser(x_mean=np.zeros(spec.dim, np.float32),
                      x_std=np.full(spec.dim, 50.0, np.float32),
                      y_mean=np.zeros(3, np.float32), y_std=np.ones(3, np.float32))
    ds = SimpleNamespace(forces=np.array([[[0.0, 0.0, 0.4]]]), extra=extra, scene_name="t",
                         spec=spec, points=[pts, pts], fixed=[np.arange(5)] * 2,
                         out_nodes=[np.arange(40)] * 2)
    export_model(tmp_path / "m", (jax.device_get(params["params"]), norm),
                 get_config("small", hidden=[16]), ds)
    predict = load_predictor(tmp_path / "m")
    geometry = (pts, np.arange(5))

    def run(force, material, shape):
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            out = predict([force], [7], material=material, geometry=(*geometry, shape))
        return out, [str(x.message) for x in w]

    corners = [(f, m, s) for f in ([0, 0, 0.4], [0.4, 0, 0])
               for m in (extra[0, :3], extra[1, :3]) for s in (extra[0, 3:], extra[1, 3:])]
    for force, material, shape in corners:
        out, warned = run(force, material, shape)
        assert np.isfinite(out).all() and out.shape == (40, 3) and not warned, warned
    _, warned = run([0, 0, 0.8], extra[0, :3], extra[0, 3:])
    assert any("force magnitude" in m for m in warned)
    _, warned = run([0, 0, 0.4], [2e-2, 10.0, 0.5], extra[0, 3:])
    assert any(m.startswith("material") for m in warned)
    _, warned = run([0, 0, 0.4], extra[0, :3], [3.0, 0.0])
    assert any(m.startswith("shape coefficients") for m in warned)
    with pytest.raises(ValueError, match="shape coefficients contain NaN"):
        run([0, 0, 0.4], extra[0, :3], [np.nan, 0.0])


@pytest.mark.parametrize("tamper, message", [
    ("nan_weight", r"params.npz: 'hidden_0/kernel' contains NaN"),
    ("wrong_shape", r"params.npz: 'hidden_1/kernel' has shape .* the config says"),
    ("truncated_json", r"model.json: not valid JSON"),
    ("array_json", r"model.json: expected a JSON object, got list"),
    ("string_version", r"model.json: version '1', this code reads 1"),
    ("no_params", r"params.npz: missing"),
    ("no_geometry", r"geometry.npz: missing \(the model was exported with its liver\)"),
])
def test_tampered_model_files_are_refused_at_load(run, tmp_path, tamper, message):
    """Every file of a model is checked when it is loaded, not at the first call: a NaN or
    misshapen weight, broken JSON, a wrong version type, a missing file; errors name it."""
    import shutil

    d = tmp_path / "model"
    shutil.copytree(run[0] / "model", d)
    meta = json.loads((d / "model.json").read_text())
    if tamper in ("nan_weight", "wrong_shape"):
        with np.load(d / "params.npz") as z:
            flat = {k: z[k] for k in z.files}
        if tamper == "nan_weight":
            flat["hidden_0/kernel"][0, 0] = np.nan
        else:
            flat["hidden_1/kernel"] = flat["hidden_1/kernel"][:, :-1]
        np.savez(d / "params.npz", **flat)
    elif tamper == "truncated_json":
        (d / "model.json").write_text((d / "model.json").read_text()[:100])
    elif tamper == "array_json":
        (d / "model.json").write_text("[1, 2]")
    elif tamper == "string_version":
        meta["version"] = "1"
        (d / "model.json").write_text(json.dumps(meta))
    elif tamper == "no_params":
        (d / "params.npz").unlink()
    else:
        (d / "geometry.npz").unlink()
    with pytest.raises(ValueError, match=message):
        load_predictor(d)


def test_a_fingerprinted_model_is_refused_when_a_file_changed_went_or_came(run, tmp_path):
    """A shipped model carries fingerprint.json (the SHA-256 of each file): it loads as it
    is, and a weight changed by one bit of data, a file deleted or one added are refused
    at load naming the file; a model without a fingerprint (trained here) is not checked."""
    import shutil

    from surrogate.model_files import write_fingerprint

    d = tmp_path / "shipped"
    shutil.copytree(run[0] / "model", d)
    write_fingerprint(d)
    x = np.ones((1, 1, 3)) * 0.1
    nodes = [[0]]
    np.testing.assert_array_equal(load_predictor(d)(x[0], nodes[0]),
                                  load_predictor(run[0] / "model")(x[0], nodes[0]))
    with np.load(d / "params.npz") as z:
        flat = {k: z[k] for k in z.files}
    flat["hidden_0/kernel"][0, 0] = np.nextafter(flat["hidden_0/kernel"][0, 0], np.inf)
    np.savez(d / "params.npz", **flat)
    with pytest.raises(ValueError, match=r"params.npz: changed since the model was"):
        load_predictor(d)
    shutil.copy(run[0] / "model" / "params.npz", d / "params.npz")
    load_predictor(d)   # the shipped bytes again
    (d / "extra.npz").write_bytes(b"x")
    with pytest.raises(ValueError, match=r"extra.npz: added since"):
        load_predictor(d)
    (d / "extra.npz").unlink()
    (d / "geometry.npz").unlink()
    with pytest.raises(ValueError, match=r"geometry.npz: missing since"):
        load_predictor(d)


def test_restrict_nodes_keeps_the_targets_of_the_kept_nodes(synth_dir):
    """A surface-only view of a dataset: every sample keeps exactly its rows at the kept nodes
    (checked against the full dataset by node id), and training examples index into it."""
    from surrogate.data import load_dataset, restrict_nodes
    from surrogate.nodewise import example_index

    ds = load_dataset(synth_dir, stream=False)
    keep = ds.out_nodes[0][::3][:40]
    sub = restrict_nodes(ds, [np.concatenate([keep, [10**7]])])  # unknown ids are ignored
    assert np.array_equal(sub.out_nodes[0], keep)
    pos = np.searchsorted(ds.out_nodes[0], keep)
    for s in (0, ds.n_samples // 2, ds.n_samples - 1):
        full = ds.targets[ds.sample_offset[s]:ds.sample_offset[s + 1]]
        part = sub.targets[sub.sample_offset[s]:sub.sample_offset[s + 1]]
        np.testing.assert_array_equal(part, full[pos])
    np.testing.assert_array_equal(sub.static, ds.static[pos])
    rows, _, tgt = example_index(sub, np.arange(sub.n_samples))
    assert rows.max() < sub.static.shape[0] and tgt.max() == sub.targets.shape[0] - 1
    with pytest.raises(ValueError, match="2 node lists for 1 geometries"):
        restrict_nodes(ds, [keep, keep])


def test_a_load_where_the_scene_never_loads_is_flagged(run, synth_dir):
    """The exported liver knows which nodes were loaded in training (the scene's rule and the
    shards' loads): a load elsewhere (here the fixed nodes) gets a warning, a trained one not."""
    from data_spec import list_shards, read_shard

    pred = load_predictor(run[0] / "model")
    seen = read_shard(list_shards(synth_dir)[0]).load_nodes
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pred([[0.0, 0.0, -0.4]], seen)
    never = np.setdiff1d(pred.fixed, pred.loadable)[:1]
    assert never.size
    with pytest.warns(UserWarning, match=rf"load node\(s\) \[{never[0]}\] never loaded"):
        pred([[0.0, 0.0, -0.4]], never)


def test_evaluating_one_fold_is_a_hold_out(synth_dir, tmp_path):
    """folds = 4, evaluate_folds = 1: one model, its metrics on the quarter it never saw."""
    cfg = get_config("small", folds=4, evaluate_folds=1, epochs=2, hidden=[16],
                     final_fit=False)
    result = train_and_evaluate(synth_dir, tmp_path, cfg, log_fn=lambda m: None)
    assert (result["folds"], result["evaluated_folds"]) == (4, 1)
    hist = json.loads((tmp_path / "history.json").read_text())
    assert list(hist) == ["fold0"]
    assert "the first 1 of 4 folds held out" in (tmp_path / "metrics.md").read_text()
    with pytest.raises(ValueError, match="evaluate_folds: expected an integer >= 0"):
        get_config("small", evaluate_folds=-1)


def test_the_trainer_thins_a_folds_training_set_and_says_how_much_it_trained_on(synth_dir,
                                                                                 tmp_path):
    """train_fraction = 0.5 on one liver: half of the 30 training simulations of a fold of
    four (40 simulations); the held-out quarter is the same, so the metrics compare."""
    common = {"folds": 4, "evaluate_folds": 1, "epochs": 2, "hidden": [16], "final_fit": False}
    full = train_and_evaluate(synth_dir, tmp_path / "full", get_config("small", **common),
                              log_fn=lambda m: None)
    half = train_and_evaluate(synth_dir, tmp_path / "half",
                              get_config("small", train_fraction=0.5, **common),
                              log_fn=lambda m: None)
    assert (full["train_livers"], full["train_simulations"]) == (1, 30)
    assert (half["train_livers"], half["train_simulations"]) == (1, 15)
    assert half["n_simulations"] == full["n_simulations"] == 40
