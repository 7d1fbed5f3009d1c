"""The modes floor of a liver never seen (surrogate.evaluate.modes_floor): the least-squares
best a basis model's modes can do at a liver's nodes, checked on fields built by hand."""

from types import SimpleNamespace

import numpy as np

from liverreg.morph import interpolation_matrix
from surrogate.evaluate import modes_floor


def test_the_floor_is_zero_in_the_span_of_the_modes_and_the_rest_outside_it():
    """Liver = template (identity placement, nodes at the template's nodes, so the
    interpolation is the identity): a field that mixes the modes has floor 0; adding a field
    orthogonal to every mode adds exactly that field's mean node norm."""
    rng = np.random.default_rng(0)
    n, k, steps = 40, 5, 3
    points = rng.uniform(0.0, 50.0, size=(n, 3))
    q = np.linalg.qr(rng.standard_normal((3 * n, k + 1)))[0].T  # k modes + one orthogonal
    modes, extra = q[:k], q[k].reshape(n, 3)
    place = SimpleNamespace(points=points, to_population=lambda x: x,
                            vectors_to_liver=lambda v: v)
    pred = SimpleNamespace(modes=modes.reshape(k, n, 3))
    interp = interpolation_matrix(points, points).tocsr()
    c = rng.normal(size=(steps, k)) * 10.0
    inside = (c @ modes).reshape(steps, n, 3)
    shard = SimpleNamespace(output_nodes=np.arange(n), n_done=steps, displacement=inside)
    assert modes_floor(pred, place, interp, [shard]) < 1e-9
    scale = np.array([1.0, 2.0, 3.0])
    shard.displacement = inside + scale[:, None, None] * extra[None]
    want = np.mean(scale[:, None] * np.linalg.norm(extra, axis=1)[None])
    np.testing.assert_allclose(modes_floor(pred, place, interp, [shard]), want, rtol=1e-9)
    # a shard that outputs every other node is fitted at those nodes only: a mix of the
    # modes there is still exact, and the orthogonal field is no longer orthogonal
    part = np.arange(0, n, 2)
    shard.output_nodes, shard.displacement = part, inside[:, part]
    assert modes_floor(pred, place, interp, [shard]) < 1e-9
    shard.displacement = inside[:, part] + extra[None, part]
    # a projection shortens the field: mean node norm <= its RMS <= the field's RMS
    rms = np.sqrt(np.mean(np.sum(extra[part] ** 2, axis=1)))
    assert 0.0 < modes_floor(pred, place, interp, [shard]) < rms
