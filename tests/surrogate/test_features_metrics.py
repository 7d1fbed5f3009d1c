import numpy as np
import pytest

from data_spec import load_scene
from surrogate.features import FeatureSpec, node_features, static_node_features
from surrogate.metrics import displacement_metrics
from tests.surrogate.conftest import ROOT


def test_feature_blocks_follow_the_scene():
    dims = {}
    for name in ("scene1_base", "scene2_two_forces", "scene3_materials"):
        spec = FeatureSpec.from_scene(load_scene(ROOT / "data_spec" / "scenes" /
                                                 f"{name}.toml"))
        dims[name] = spec.dim
        assert len(spec.names()) == spec.dim
    # 11 static + 7 per force (+ c1, m1, K when the material varies)
    assert dims == {"scene1_base": 18, "scene2_two_forces": 25, "scene3_materials": 21}
    s4 = FeatureSpec.from_scene(load_scene(ROOT / "data_spec" / "scenes" /
                                           "scene4_phantoms.toml"), n_shape=27)
    assert s4.dim == 18 + 27 and s4.material_dim == 0


def test_static_and_load_features_by_hand():
    pts = np.array([[0.0, 0, 0], [2.0, 0, 0], [0.0, 4, 0], [0.0, 0, 6]])
    fixed = np.array([1, 2])
    st = static_node_features(pts, fixed)
    # node 0: closest fixed node is 1 at (2, 0, 0); centroid of fixed = (1, 2, 0)
    np.testing.assert_allclose(st[0], [0, 0, 0, 2, 0, 0, 2, 1, 2, 0, np.sqrt(5)])
    # node 3: closest fixed is 1 (dist sqrt(40)) vs 2 (sqrt(52))
    np.testing.assert_allclose(st[3, 3:7], [2, 0, -6, np.sqrt(40)])
    f = node_features(st, np.array([[0.0, 0, -0.4]]), pts[[3]], np.zeros(0))
    assert f.shape == (4, 18)
    np.testing.assert_allclose(f[0, 11:], [0, 0, -0.4, 0, 0, 6, 6])


def test_metrics_by_hand():
    true = np.array([[0.0, 0, 0], [1.0, 2, 2], [3.0, 0, 4]])
    pred = np.array([[0.0, 0, 0.5], [1.0, 2, 0], [0.0, 0, 0]])
    m = displacement_metrics(pred, true)
    # errors: (0,0,.5) -> .5; (0,0,-2) -> 2; (-3,0,-4) -> 5
    assert m["mee"] == pytest.approx((0.5 + 2 + 5) / 3)
    assert m["mae_z"] == pytest.approx((0.5 + 2 + 4) / 3)
    assert m["pct_ee_lt_1mm"] == pytest.approx(100 / 3)
    assert m["pct_ee_lt_3mm"] == pytest.approx(200 / 3)
    # 95th percentile of (0.5, 2, 5), linear interpolation: rank 0.95 * 2 = 1.9 -> 2 + 0.9 * 3
    assert m["ee_p95"] == pytest.approx(4.7)
    assert m["corr_x"] == pytest.approx(np.corrcoef(pred[:, 0], true[:, 0])[0, 1])


def test_training_and_inference_build_the_same_features():
    """train.batch_features (per example, inside jit) and features.node_features (per load
    case, used by the exported predictor) must lay out identical feature vectors."""
    import jax.numpy as jnp

    from surrogate.nodewise import batch_features

    rng = np.random.default_rng(0)
    pts = rng.normal(size=(9, 3))
    st = static_node_features(pts, np.array([0, 4]))
    forces = rng.normal(size=(2, 2, 3))          # 2 samples, 2 loads
    lp = pts[[[1, 2], [3, 5]]]
    extra = rng.normal(size=(2, 3))
    data = {"static": jnp.asarray(st), "forces": jnp.asarray(forces),
            "load_points": jnp.asarray(lp), "extra": jnp.asarray(extra)}
    rows = np.arange(9)
    got = np.asarray(batch_features(data, jnp.asarray(rows), jnp.full(9, 1)))
    want = node_features(st, forces[1], lp[1], extra[1])
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)


def test_learning_rate_rules_are_optax_transforms():
    """plateau: x0.1 once ``lr_patience`` epochs pass without a relative improvement of 1e-4
    (counted again from zero after each reduction), judged on the mean value of an epoch of
    steps; decay: / 1.5 per epoch; read from the optimiser state, never written into it."""
    import jax.numpy as jnp

    from surrogate.config import get_config
    from surrogate.engine import learning_rate_now, optimizer

    steps = 3
    cfg = get_config("small", learning_rate=1e-3, lr_patience=2)
    tx = optimizer(cfg, steps)
    params = {"w": jnp.ones(2)}
    state = tx.init(params)
    lrs = []
    for epoch, v in enumerate((1.0, 0.9, 0.95, 0.95, 0.95, 0.95, 0.8)):
        for _ in range(steps):
            _, state = tx.update({"w": jnp.ones(2)}, state, params, value=jnp.float32(v))
        lrs.append(learning_rate_now(cfg, state, (epoch + 1) * steps, steps))
    np.testing.assert_allclose(lrs, [1e-3, 1e-3, 1e-3, 1e-4, 1e-4, 1e-5, 1e-5], rtol=1e-6)
    decay = get_config("small", learning_rate=1e-3, lr_rule="decay")
    assert [learning_rate_now(decay, None, k * steps, steps) for k in (1, 2, 3)] == \
        [1e-3 / 1.5, 1e-3 / 1.5**2, 1e-3 / 1.5**3]
    # the update a decay optimiser applies in the second epoch is the rate's: Adam's first
    # step moves each weight by the learning rate (sign of the gradient)
    tx = optimizer(decay, steps)
    state = tx.init(params)
    moves = []
    for _ in range(2 * steps):
        u, state = tx.update({"w": jnp.ones(2)}, state, params)
        moves.append(float(-u["w"][0]))
    np.testing.assert_allclose(moves[:steps], [1e-3] * steps, rtol=1e-4)
    np.testing.assert_allclose(moves[steps:], [1e-3 / 1.5] * steps, rtol=1e-4)


def test_weight_decay_is_the_gradient_of_the_l2_penalty_on_the_weight_matrices():
    """The engine's optimiser with l2 = 0.1 adds 0.1 w to the gradient of every kernel (the
    penalty l2 |w|^2 / 2), not of the biases. Adam's first step is -lr * sign(gradient)
    (m / sqrt(v) = g / |g|), so the sign of each step says which gradient Adam saw. By hand:
    kernel w = (2, -3), g = (0.05, 0.05): with decay g' = (0.25, -0.25), steps (-lr, +lr);
    without, g' = g, steps (-lr, -lr). Bias b = 5, g = -0.1: decayed it would be 0.4 and step
    -lr; it must stay -0.1 and step +lr."""
    import jax.numpy as jnp

    from surrogate.config import get_config
    from surrogate.engine import kernel_mask, optimizer

    params = {"layer": {"kernel": jnp.array([2.0, -3.0]), "bias": jnp.array([5.0])}}
    assert kernel_mask(params) == {"layer": {"kernel": True, "bias": False}}
    g = {"layer": {"kernel": jnp.array([0.05, 0.05]), "bias": jnp.array([-0.1])}}
    lr = 1e-3
    for l2, kernel_steps in ((0.1, [-lr, lr]), (0.0, [-lr, -lr])):
        tx = optimizer(get_config("small", l2=l2, lr_rule="decay", learning_rate=lr), 10)
        u, _ = tx.update(g, tx.init(params), params)
        np.testing.assert_allclose(u["layer"]["kernel"], kernel_steps, rtol=1e-4)
        np.testing.assert_allclose(u["layer"]["bias"], [lr], rtol=1e-4)


def test_config_names_exactly_the_registered_designs():
    from surrogate.config import get_config
    from surrogate.designs import DESIGNS

    assert all(DESIGNS[n].name == n for n in DESIGNS)
    with pytest.raises(ValueError, match="design: expected 'nodewise' or 'basis'"):
        get_config("small", design="graph")


def test_the_one_mee_helper_by_hand():
    """|(3, 4, 0)| = 5 and |(0, 0, 1)| = 1: MEE 3 whatever the fields' layout (cases x nodes
    x 3, or rows of nodes x 3); each case's own mean apart."""
    from surrogate.metrics import case_mee, mee

    err = np.array([[[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]], [[0.0, 0.0, 2.0], [0.0, 0.0, 4.0]]])
    assert mee(err) == pytest.approx((5 + 1 + 2 + 4) / 4)
    assert mee(err.reshape(2, -1)) == mee(err) == mee(err + 7.0, np.full_like(err, 7.0))
    np.testing.assert_allclose(case_mee(err, 0.0 * err), [3.0, 3.0])
