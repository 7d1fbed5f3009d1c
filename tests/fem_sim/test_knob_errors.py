"""The price list's error measures (fem_sim.batch.knob_run.field_errors) on fields whose errors
are known by hand: a field 10 % too small everywhere is 10 % too stiff (signed -0.1), its
errors are 10 % of each node's displacement, relative to the reference's largest component."""

import numpy as np
import pytest

from fem_sim.batch.knob_run import field_errors


def test_errors_of_a_uniformly_stiffer_field():
    u_ref = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, -3.0]])
    nodes = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [20.0, 0.0, 0.0]])
    e = field_errors(0.9 * u_ref, u_ref, nodes)
    # |u - u_ref| = 0.1, 0.2, 0.3 mm; the largest reference component is 3 mm
    assert e["mean"] == pytest.approx(0.2) and e["max"] == pytest.approx(0.3)
    assert e["rel_mean"] == pytest.approx(0.2 / 3) and e["rel_max"] == pytest.approx(0.1)
    assert e["signed"] == pytest.approx(-0.1) and "inside_mean" not in e
    assert field_errors(1.5 * u_ref, u_ref, nodes)["signed"] == pytest.approx(0.5)
    # an error orthogonal to the reference field is no stiffness: signed 0, error its size
    rot = u_ref[:, [1, 0, 2]] * [1, -1, 0]   # each node's displacement turned off u_ref
    assert field_errors(u_ref + 0.1 * rot, u_ref, nodes)["signed"] == pytest.approx(0.0)


def test_a_nodal_load_measures_outside_the_ball_and_reports_inside_apart():
    u_ref = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, -3.0]])
    nodes = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [20.0, 0.0, 0.0]])
    u = u_ref.copy()
    u[0] += [5.0, 0.0, 0.0]        # the load node: no converged limit there
    u[1:] *= 0.9
    e = field_errors(u, u_ref, nodes, load_point=[1.0, 0.0, 0.0], radius=5.0)
    assert e["inside_mean"] == pytest.approx(5.0) and e["inside_max"] == pytest.approx(5.0)
    assert e["mean"] == pytest.approx(0.25) and e["max"] == pytest.approx(0.3)
    assert e["signed"] == pytest.approx(-0.1)   # over the nodes outside only
