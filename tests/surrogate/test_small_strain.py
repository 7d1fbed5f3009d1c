"""The small-strain base as a strategy (:mod:`surrogate.small_strain`): the kinds by their
config value, what each says of itself, and the one Green's-function product by hand."""

import numpy as np
import pytest

from surrogate.small_strain import BASES, LINEAR, NONE, SECOND_ORDER, base_of, green_product


def test_each_config_value_is_a_kind_that_knows_what_it_needs():
    assert [base_of(k) for k in (0, 1, 2)] == [NONE, LINEAR, SECOND_ORDER] == list(
        BASES.values())
    for bad in (3, -1, True, 1.5, "1"):
        with pytest.raises(ValueError, match="linear_base: expected one of"):
            base_of(bad)
    assert NONE.whole and not LINEAR.whole and not SECOND_ORDER.whole
    assert LINEAR.from_green and not SECOND_ORDER.from_green and not NONE.from_green
    # responses of order 2 hold the linear ones; order 1 does not hold the second term
    assert LINEAR.served_by(2) and LINEAR.served_by(1) and not SECOND_ORDER.served_by(1)
    assert LINEAR.liver_command("S.toml", "D") == "fem_sim linear S.toml --out D --order 1 --green"
    assert SECOND_ORDER.population_command("D") == "fem_sim linear --population D --order 2"
    assert LINEAR.over_green_refusal() is None
    assert "make patient distils it" in SECOND_ORDER.over_green_refusal()
    assert "places it without a base" in NONE.over_green_refusal()
    assert "make liver LIVER=... MODEL=<this run>" in LINEAR.rest_only()


def test_the_greens_function_product_by_hand():
    """Two unit responses on two output nodes: node 0's response to a unit x force is
    (1, 0, 0) at output 0 and (0, 2, 0) at output 1; node 1's to a unit z force is (0, 0, 3)
    at both. A case of 0.5 N along x at node 0 and 2 N along z at node 1 gives
    (0.5, 0, 6) and (0, 1, 6); the same at output 1 alone."""
    green = np.zeros((2, 3, 2, 3))
    green[0, 0, 0] = [1.0, 0.0, 0.0]
    green[0, 0, 1] = [0.0, 2.0, 0.0]
    green[1, 2, :] = [0.0, 0.0, 3.0]
    forces = np.array([[[0.5, 0.0, 0.0], [0.0, 0.0, 2.0]]])
    u = green_product(green, [[0, 1]], forces)
    np.testing.assert_allclose(u, [[[0.5, 0.0, 6.0], [0.0, 1.0, 6.0]]])
    np.testing.assert_allclose(green_product(green, [[0, 1]], forces, columns=[1]),
                               [[[0.0, 1.0, 6.0]]])
