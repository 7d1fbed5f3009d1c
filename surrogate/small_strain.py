"""The small-strain base a model may learn the rest of (config ``linear_base``), as a strategy:
each kind says what the model's field is, how a liver's base is built, how it comes back at
run time and what a command says when it cannot be used. Callers ask the kind
(:func:`base_of`), never its number.

- ``none`` (0): the model's field is the whole field; predict-liver places it on any liver.
- ``linear`` (1, config ``population_green``): each liver's linear response, which for any
  nodal load is the Green's function of the liver's own mesh contracted with the force
  (``fem_sim linear --green``: one factorisation, a unit response at every surface node), so
  ``make liver`` gives a new liver's whole field with no FE simulation and no training
  (:class:`surrogate.over_green.OverGreen`).
- ``second_order`` (2, config ``population_linear``): the linear response and its
  second-order term in the load, which needs a solve per load: ``make patient`` distils it
  into the patient's own model.

The contraction green[node] . force is :func:`green_product`, the one place it is written.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class SmallStrainBase:
    """One kind of base (see the module docstring)."""

    name: str
    order: int          # of the load series: 0 none, 1 the linear response, 2 with its square
    config: str         # the shipped config that trains over it

    @property
    def whole(self) -> bool:
        """Whether the model's field is the whole field (no base under it)."""
        return self.order == 0

    @property
    def from_green(self) -> bool:
        """Whether a liver's Green's function gives the base of any nodal load at run time."""
        return self.order == 1

    @property
    def words(self) -> str:
        """Its name as a report says it ("second order")."""
        return self.name.replace("_", " ")

    @property
    def use(self) -> str:
        """How a user gets a whole field from a model over this base: the report's words."""
        return ("placed on any liver (predict-liver)" if self.whole else
                "over the liver's Green's function (make liver)" if self.from_green else
                "over the liver's own base (make patient)")

    def served_by(self, order: int) -> bool:
        """Whether small-strain responses of ``order`` hold this base (order 2 holds 1)."""
        return order >= self.order

    def population_command(self, data) -> str:
        """The command that builds every liver's base of a population dataset."""
        return f"fem_sim linear --population {data} --order {self.order}"

    def liver_command(self, scene, data) -> str:
        """The command that builds one liver's base (its truth or patient scene)."""
        return (f"fem_sim linear {scene} --out {data} --order {self.order}"
                + (" --green" if self.from_green else ""))

    def rest_only(self) -> str:
        """Why the model alone gives no whole field, and the commands that add its base."""
        return (f"this model predicts what a liver's small-strain base misses (base "
                f"{self.name!r}, config {self.config}), not a whole field: a whole field needs "
                "the base of the liver's own mesh (fem_sim linear) added to it (call with "
                "rest=True), which `make liver LIVER=... MODEL=<this run> AT=...` does for a "
                "new liver over its linear response (base 'linear': "
                "surrogate.over_green.OverGreen) and `make patient LIVER=... MODEL=<this run> "
                "K=0` over the second-order one")

    def over_green_refusal(self) -> str | None:
        """Why a model over this base cannot be added to a liver's Green's function (None
        when it can).
        """
        if self.from_green:
            return None
        return (f"the model is not one of the rest over a liver's linear response (base "
                f"{self.name!r}, config {self.config}; base 'linear' expected: "
                "population_green); " + ("predict-liver places it without a base"
                                        if self.whole else "a second-order base needs a "
                                        "solve per load: make patient distils it"))


NONE = SmallStrainBase("none", 0, "population_basis")
LINEAR = SmallStrainBase("linear", 1, "population_green")
SECOND_ORDER = SmallStrainBase("second_order", 2, "population_linear")
BASES = {b.order: b for b in (NONE, LINEAR, SECOND_ORDER)}


def base_of(order) -> SmallStrainBase:
    """The kind of base of a config's ``linear_base`` value; ValueError naming the kinds."""
    if isinstance(order, bool) or order not in BASES:
        raise ValueError(f"linear_base: expected one of {sorted(BASES)} ("
                         + ", ".join(f"{k}: {b.name}" for k, b in BASES.items())
                         + f"), got {order!r}")
    return BASES[order]


def green_product(green: np.ndarray, rows: np.ndarray, forces: np.ndarray,
                  columns=None) -> np.ndarray:
    """(cases, n_out, 3) mm: the small-strain response of the loads, the sum over each case's
    loads of green[row] . force; ``green`` (n_g, 3, n_out, 3) mm/N, ``rows`` (cases, L) its
    rows under the load nodes, ``forces`` (cases, L, 3) N; ``columns``: only these of its
    output nodes (taken after the rows: a few loads' rows, not the whole function, copied).
    """
    g = green[np.asarray(rows)]                    # (cases, L, 3, n_out, 3)
    if columns is not None:
        g = g[:, :, :, np.asarray(columns)]
    return np.einsum("slcnd,slc->snd", g, np.asarray(forces, dtype=np.float64),
                     dtype=np.float64)
