"""The design record the studies write and the reports read (surrogate.reports): a round trip
keeps every field, unknown ones included, and the latency cell asks the small-strain base how
a whole field is had, never its order."""

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
