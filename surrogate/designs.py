"""The designs the training engine knows, by the name a config gives (``design = ...``).

A design is an object with ``name``, ``check(ds)``, ``problem(ds, train, val, cfg, rng)`` (an
:class:`surrogate.engine.Problem`), ``model(problem, params)``, ``predict_samples(ds, model,
cfg, samples)``, ``export_parts(model)`` and ``shape_rule`` (the shape a model trained on a
population is told for a liver outside it); adding one is adding an entry here.
"""

from __future__ import annotations

from surrogate.basis import Basis
from surrogate.nodewise import NodeWise
from surrogate.population_basis import PopulationBasis

DESIGNS = {d.name: d for d in (NodeWise(), Basis(), PopulationBasis())}
