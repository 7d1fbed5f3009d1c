"""surrogate.patient.study: the figures docs/patient.md prints from its curves, on two
hand-made livers whose every figure is worked out in the comments."""

import pytest

from surrogate.patient import study


def _curves() -> list[dict]:
    return [
        {"liver": "A", "place_seconds": 60.0, "fe_seconds": {"0": 10.0, "5": 50.0},
         "linear_seconds": 30.0,
         "points": {"0": {"population": 1.0, "linear": 0.4, "linear_rest": 0.3,
                          "patient_model": 0.6, "adapt_seconds": {"distil": 20.0}},
                    "5": {"population": 1.0, "patient_model": 0.45,
                          "adapt_seconds": {"correct": 40.0, "distil": 20.0},
                          "linear_rest_weighted": 0.25, "rest_weight": 0.8}},
         "held_out_sims": {"0": {"mee_mm": [0.2, 0.8, 0.3], "peak_mm": [5.0, 40.0, 10.0]},
                           "5": {"mee_mm": [0.1, 0.6, 0.2], "peak_mm": [5.0, 40.0, 10.0]}}},
        {"liver": "B", "place_seconds": 30.0, "fe_seconds": {"0": 10.0, "5": 50.0},
         "linear_seconds": 30.0,
         "points": {"0": {"population": 2.0, "linear": 0.5, "linear_rest": 0.6,
                          "patient_model": 0.9, "adapt_seconds": {"distil": 10.0}},
                    "5": {"population": 2.0, "patient_model": 0.7,
                          "adapt_seconds": {"distil": 10.0},
                          "linear_rest_weighted": 0.6, "rest_weight": 1.0}},
         "held_out_sims": {"0": {"mee_mm": [0.1, 0.5], "peak_mm": [3.0, 35.0]}}},
    ]


def test_minutes_add_the_steps_from_the_liver_file_to_the_patient_model():
    a = _curves()[0]
    # placing 60 s + start-up 30 s + the K = 5 solves 50 s + fem_sim linear 30 s + adapting 60 s
    assert study.patient_minutes(a, 5, start=30.0) == pytest.approx(230.0 / 60)
    assert study.patient_minutes(a, 0, start=30.0) == pytest.approx(150.0 / 60)
    del a["points"]["0"]["adapt_seconds"]   # K = 0 without the responses: placing alone
    assert study.patient_minutes(a, 0, start=30.0) == pytest.approx(1.0)
    del a["points"]["0"]["patient_model"]   # ... and the population model's MEE
    assert study.patient_mee(a, 0) == 1.0


def test_curve_figures_are_the_hand_counted_medians_goals_and_weights():
    f = study.curve_figures(_curves(), (0, 5), start=30.0, goal_mm=0.5, goal_minutes=3.0)
    assert f["medians"] == [(0, pytest.approx(0.75), 2), (5, pytest.approx(0.575), 2)]
    # A reaches 0.5 mm at K = 5 (0.45), B never (0.9, 0.7)
    assert f["reached"] == [5, None]
    # within 3 min: A only K = 0 (2.5 min; K = 5 takes 3.83), B both (1.83, 2.5): its best K = 5
    assert f["best_within"] == [0, 5]
    assert f["rest_vs"] == {"linear": [0.4, 0.5], "rest": [0.3, 0.6], "lower": 1}
    (w,) = f["weights"]   # weighted 0.25 / 0.6 against weight one 0.3 / 0.6
    assert (w["k"], w["lower"], w["higher"]) == (5, 1, 0)
    assert (w["median"], w["one"]) == (pytest.approx(0.425), pytest.approx(0.45))
    assert w["livers"] == [("A", 0.8), ("B", 1.0)] and f["tuned"] == {}
    unknown = study.curve_figures(_curves(), (0, 5), None, 0.5, 3.0)
    assert unknown["best_within"] == [None, None]   # no start-up measured: no time goal


def test_load_size_splits_the_held_out_simulations_at_the_peak():
    s = study.load_size(_curves(), big_peak_mm=30.0, goal_mm=0.5)
    # K = 0 pooled: MEE 0.2 0.8 0.3 0.1 0.5 against peaks 5 40 10 3 35: the same order
    assert s["rho"] == pytest.approx(1.0) and (s["n"], s["livers"], s["big"]) == (5, 2, 2)
    assert s["big_mee"] == pytest.approx(0.65) and s["small_mee"] == pytest.approx(0.2)
    assert (s["kmax"], s["livers_kmax"]) == (5, 1)   # only A kept K = 5's simulations
    assert s["big_mee_kmax"] == pytest.approx(0.6) and s["small_mee_kmax"] == pytest.approx(0.15)
    # A's mean K = 0 MEE 0.433 is within 0.1 mm of the goal: 1 large one, 0.25 mm without it
    assert s["per"] == [("A", 1, pytest.approx(0.25))]
    assert study.load_size([{"liver": "C", "points": {}}], 30.0, 0.5) is None
