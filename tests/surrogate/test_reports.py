"""The design record the studies write and the reports read (surrogate.reports): a round trip
keeps every field, unknown ones included, and the latency cell asks the small-strain base how
a whole field is had, never its order."""

import pytest

from surrogate.reports import DesignRecord, design_label, xyz
from surrogate.small_strain import LINEAR, NONE, SECOND_ORDER


def _metrics(skill_mean=0.1, skill_median=0.08):
    return {"skill": 0.2, "per_liver_mee": {"skill_mean": skill_mean,
                                            "skill_median": skill_median, "median": 0.3}}


def test_a_record_goes_to_json_and_back_with_the_fields_it_does_not_know():
    d = {"config": "population_green", "metrics": _metrics(), "ms_own": 0.5, "ms_big": 0.7,
         "run": "bench/results/x", "floor": {"held_out": 0.2}}
    r = DesignRecord.from_json(d)
    assert r.extra == {"run": "bench/results/x", "floor": {"held_out": 0.2}}
    assert r.to_json() == d


def test_the_latency_cell_says_how_a_whole_field_is_had():
    exported = DesignRecord("population_basis", _metrics(), ms_own=0.123, ms_big=0.456)
    assert exported.use_cell() == "0.12 / 0.46"
    assert exported.use_cell("{big:.2f}") == "0.46"
    assert exported.base is None
    assert DesignRecord("population_basis", _metrics()).use_cell() == "not exported"
    green = DesignRecord("population_green", _metrics(), base_alone={"order": 1})
    patient = DesignRecord("population_linear", _metrics(), base_alone={"order": 2})
    assert green.base is LINEAR and patient.base is SECOND_ORDER
    assert green.use_cell() == "over the liver's Green's function (make liver)"
    assert patient.use_cell() == "over the liver's own base (make patient)"
    assert "predict-liver" in NONE.use


def test_cells():
    assert DesignRecord("x", _metrics(0.1234, 0.0567)).per_liver_skill() == "0.123 / 0.057"
    assert xyz({"mae_x": 1, "mae_y": 2.5, "mae_z": 0.1234}, "mae") == "1.000 / 2.500 / 0.123"
    assert design_label("population_basis", {"folds": 10}).endswith(
        "(`population_basis`, folds = 10)")


def test_surgical_rows_average_a_livers_cases_then_take_the_median_and_worst_liver():
    """surrogate.reports.surgical_per_liver / surgical_curve on three hand-made livers: a
    liver's figure is the mean over its converged cases at that pull, a curve's the median
    and worst over the livers; a failed case counts nowhere, a liver without the model's
    rows leaves the model out of the curve."""
    from surrogate.reports import surgical_curve, surgical_per_liver

    def step(pull, mee, force_error, model=None):
        e = {"mee": mee, "p95": 2 * mee, "lt3": 100 - mee, "mean_u": 10.0}
        s = {"pull": pull, "base": e, "naive": {**e, "mee": 5.0}, "force_error": force_error,
             "fe_force": [3.0, 4.0, 0.0]}
        return s | ({"model": {**e, "mee": model}, "model_force_error": force_error / 2}
                    if model is not None else {})

    def liver(name, cases):
        return {"liver": name, "grasps": [{"status": st, "steps": steps} for st, steps in cases]}

    records = [liver("A", [("ok", [step(40.0, 1.0, 10.0, 0.5)]),
                           ("ok", [step(40.0, 3.0, 30.0, 1.5)]),
                           ("failed", [step(40.0, 99.0, 99.0, 99.0)])]),
               liver("B", [("ok", [step(40.0, 4.0, 50.0, 1.0)])]),
               liver("C", [("ok", [step(40.0, 6.0, 20.0, 4.0)])])]
    per = surgical_per_liver(records, "grasps", "pull", 40.0)
    # A: the mean of its two converged cases
    assert per["A"]["base"]["mee"] == pytest.approx(2.0)
    assert per["A"]["model"]["mee"] == pytest.approx(1.0)
    assert per["A"]["force_error"] == pytest.approx(20.0)
    assert per["A"]["model_force_error"] == pytest.approx(10.0)
    assert per["A"]["fe_force"] == pytest.approx(5.0)
    (row,) = surgical_curve(records, "grasps", "pull", (40.0, 30.0))   # nobody reached 30
    # livers' base MEE 2, 4, 6; model 1, 1, 4; force errors 20, 50, 20 and half of them
    assert (row["base"]["mee_median"], row["base"]["mee_worst"]) == (4.0, 6.0)
    assert (row["model"]["mee_median"], row["model"]["mee_worst"]) == (1.0, 4.0)
    assert (row["force_error_median"], row["force_error_worst"]) == (20.0, 50.0)
    assert (row["model"]["force_median"], row["model"]["force_worst"]) == (10.0, 25.0)
    assert row["base"]["lt3_worst"] == 94.0 and row["livers"] == 3
    del records[2]["grasps"][0]["steps"][0]["model"]
    assert "model" not in surgical_curve(records, "grasps", "pull", (40.0,))[0]
