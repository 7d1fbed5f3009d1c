"""The liver-size hint names the flag or key to set, and never suggests metres for a liver
that is too large."""

import re

from data_spec.units import span_problem


def test_the_hint_names_the_flag_and_the_likely_unit():
    assert span_problem(190.0, "liver.stl") is None
    assert "give --scale-to-mm 1000" in span_problem(0.19, "liver.stl")
    assert "centimetres, give --scale-to-mm 10" in span_problem(19.0, "liver.stl")
    big = span_problem(1900.0, "liver.stl", "geometry.scale_to_mm")
    assert "geometry.scale_to_mm 0.1" in big and not re.search(r"\bmetres\b", big)
