"""surrogate.patient_errors: where a patient model's error is, on fields whose answers are known."""

import numpy as np
import pytest

from surrogate.patient_errors import error_sources, per_simulation, projection_floor


def _fields(rng, n, nodes=50):
    return rng.normal(size=(n, nodes, 3))


def test_the_projection_floor_is_zero_in_the_span_and_the_field_itself_outside_it():
    rng = np.random.default_rng(0)
    train = _fields(rng, 6)
    inside = np.einsum("hk,knc->hnc", rng.normal(size=(4, 6)), train)
    assert projection_floor(train, inside) < 1e-10
    # a field orthogonal to every training field (zero on the nodes they use, and they
    # are zero where it is not): its projection is zero, so the floor is its own mean norm
    train[:, :25], outside = 0.0, _fields(rng, 3)
    outside[:, 25:] = 0.0
    expected = np.linalg.norm(outside, axis=-1).mean()
    assert projection_floor(train, outside) == pytest.approx(expected, rel=1e-12)


def test_error_sources_on_a_made_up_patient():
    """Held-out fields in the training span, errors proportional to the displacement (alike at
    every load step), the correction worse than the population on exactly one simulation.
    """
    rng = np.random.default_rng(2)
    train = _fields(rng, 8)
    sims = np.repeat(np.arange(4), 3)                          # 4 held-out sims, 3 steps
    steps = np.tile([0.2, 0.6, 1.0], 4)
    shapes = np.einsum("sk,knc->snc", rng.normal(size=(4, 8)), train)
    true = shapes[sims] * steps[:, None, None]
    noise = rng.normal(size=true.shape)
    noise /= np.linalg.norm(noise, axis=-1, keepdims=True)      # unit vectors at every node
    size = np.linalg.norm(true, axis=-1, keepdims=True)
    corrected = true + 0.1 * size * noise                       # 10 % of the displacement
    population = true + 0.3 * size * noise
    population[sims == 2] = true[sims == 2] + 0.05 * size[sims == 2] * noise[sims == 2]
    points = rng.normal(size=(12, 3)) * 50.0
    train_points = points[:8] + 1.0
    out = error_sources(train, train_points, true, points, population, corrected, sims)
    assert out["projection_floor_mm"] < 1e-10
    # each node's error is 10 % of its displacement, so the mean error is 10 % of the mean
    # displacement at every step
    assert out["relative_first_step"] == pytest.approx(0.1, rel=1e-9)
    assert out["relative_last_step"] == pytest.approx(0.1, rel=1e-9)
    assert out["worse_than_population"] == 1 and out["simulations"] == 4
    assert out["corrected_mm"] < out["population_mm"]
    assert out["spearman_displacement"] == pytest.approx(1.0)   # error = 0.1 x displacement
    # each held-out simulation's load placed farther from the training loads the larger its
    # displacement (so its error): the error follows the distance, rank for rank; placed
    # nearer instead, it follows it in reverse
    rank = np.argsort(np.argsort([np.linalg.norm(true[sims == s], axis=-1).mean()
                                  for s in range(4)]))
    train_points = np.zeros((8, 3))
    for sign in (1.0, -1.0):
        points = np.zeros((12, 3))
        points[:, 0] = 100.0 + sign * 10.0 * rank[sims]
        out = error_sources(train, train_points, true, points, population, corrected, sims)
        assert out["spearman_nearest_load"] == pytest.approx(sign)
        assert out["nearest_load_mm"] == pytest.approx(100.0 + sign * 15.0)   # median of 4


def test_per_simulation_takes_each_simulations_mean_error_and_its_last_steps_peak():
    """Two simulations of two load steps on two nodes, every number by hand."""
    true = np.zeros((4, 2, 3))
    true[0, 0, 0], true[1, 0, 0], true[1, 1, 1] = 1.0, 2.0, 4.0     # sim 5: steps 0, 1
    true[2, 1, 2], true[3, 1, 2] = 3.0, 6.0                          # sim 2: steps 2, 3
    pred = true.copy()
    pred[1, 0, 0] += 0.4               # sim 5, step 1: node errors 0.4, 0 -> MEE 0.2
    pred[3, :, 0] += [0.3, 0.1]        # sim 2, step 3: node errors 0.3, 0.1 -> MEE 0.2
    pred[2, 1, 2] -= 0.6               # sim 2, step 2: node errors 0, 0.6 -> MEE 0.3
    out = per_simulation(pred, true, np.array([5, 5, 2, 2]))
    assert out["sim"] == [2, 5]
    assert out["mee_mm"] == pytest.approx([(0.3 + 0.2) / 2, (0.0 + 0.2) / 2])
    # the last step's largest node displacement: sim 2 node 1 (6), sim 5 node 1 (4)
    assert out["peak_mm"] == pytest.approx([6.0, 4.0])
    # mean over both steps and both nodes: sim 2 (0 + 3 + 0 + 6) / 4, sim 5 (1 + 0 + 2 + 4) / 4
    assert out["mean_mm"] == pytest.approx([9 / 4, 7 / 4])
