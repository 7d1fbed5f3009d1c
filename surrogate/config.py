"""Trainer configurations: plain dicts, ``get_config(name)`` plus overrides (Flax-examples style).

The paper's Table 3 architectures: scene 1 (500, 300, 100, 50); scenes 2-3 deeper variants;
scene 4 five layers of 500. "small" is the CI/demo size.
"""

from __future__ import annotations

import copy

from data_spec.checks import is_int, is_num
from surrogate.small_strain import BASES

BASE = {
    "design": "nodewise",      # "nodewise": the paper's MLP per node; "basis": a reduced basis
                               # (surrogate/basis.py), one liver only
    "modes": 64,               # basis: number of modes
    "hidden": [128, 128, 128],
    "shape_inputs": "all",     # population_basis: how many leading shape coefficients the
                               # network is told ("all" or a number; the rest it never sees)
    "load_context": False,     # population_basis: tell the network where each load sits on
                               # the liver (template place, offset and distance to the fixed
                               # region; surrogate/population_basis.py)
    "linear_base": 0,          # population_basis: learn the FE fields less each liver's
                               # small-strain base of this order (the kinds of
                               # surrogate/small_strain.py: 0 none, 1 linear, 2 second order;
                               # fem_sim linear --population builds it)
    "ensemble": 1,             # basis designs: networks trained on the same modes from other
                               # initialisations and batch orders; their coefficients averaged
                               # (one mode product per call whatever their number)
    "shared_loads": False,     # basis designs with several loads: one network for every load
                               # (its blocks summed over the loads; surrogate/basis.py)
    "loss": "mse",             # basis designs: "mse", the mean squared field error; "rms", the
                               # mean over fields of their root-mean-square error (weighs each
                               # field by its error, not its error squared, as MEE does);
                               # "mee", the mean Euclidean node error of the decoded fields
    "dropout": 0.0,            # node-wise only
    "l2": 0.0,                 # weight decay coefficient (added to the loss as l2 * |w|^2 / 2)
    "input_noise": 0.0,        # std of Gaussian noise on normalised inputs during training
    "shape_noise": None,       # population_basis: its std on the shape coefficients instead
                               # (None: input_noise), a liver perturbed within the population
    "batch_size": 2048,
    "learning_rate": 1e-3,
    "lr_rule": "plateau",      # "plateau": x0.1 after 2 epochs without val improvement;
                               # "decay": / 1.5 every epoch
    "lr_patience": 2,
    "epochs": 60,
    "early_stopping": 6,       # epochs without validation improvement before stopping
    "node_fraction": 1.0,      # examples per epoch = this fraction of all training examples
    "inner_val_fraction": 0.1,  # simulations of the training folds held out for early stopping
    "folds": 5,
    "evaluate_folds": 0,       # train and evaluate only the first n folds (0: all): with
                               # folds = 8 and 1, a hold-out of 1/8 of the simulations/livers
    "final_fit": True,         # train the exported model on all simulations after CV
    "phantoms_in_training": True,  # phantoms mixed into liver files (geometry.phantoms) are
                               # trained on in every fold; false leaves them out (to measure)
    "train_fraction": 1.0,     # learning curves, on the same held-out folds: this fraction of
                               # each fold's training livers (simulations, for one liver)
    "simulations_per_liver": 0,  # and each training liver's first n simulations (0: all)
    "seed": 0,
    "dtype": "float32",
    "stream": "auto",          # targets memory-mapped from disk: True, False, or "auto" (when
                               # they would take more than half of the available memory)
}

CONFIGS = {
    "small": {},
    "paper_scene1": {"hidden": [500, 300, 100, 50], "epochs": 100, "folds": 10,
                     "node_fraction": 0.25},
    "paper_scene2": {"hidden": [500, 500, 300, 100, 50], "epochs": 100, "folds": 10,
                     "node_fraction": 0.25},
    "paper_scene3": {"hidden": [500, 500, 300, 100, 50], "epochs": 100, "folds": 10,
                     "node_fraction": 0.25},
    "paper_scene4": {"hidden": [500, 500, 500, 500, 500], "epochs": 100, "folds": 10,
                     "node_fraction": 0.1},
    # The real-time design (docs/realtime.md): 64 modes of the training fields, a 256 x 2
    # network from the loads to their coefficients; trained on whole fields, not nodes.
    "basis": {"design": "basis", "modes": 64, "hidden": [256, 256], "batch_size": 128,
              "epochs": 400, "early_stopping": 30, "lr_patience": 8, "folds": 10,
              # two forces: one network for both (docs/table4.md, scene 2)
              "shared_loads": True,
              # weight decay and five networks averaged: trained on a few hundred fields the
              # plain network fits them far better than held-out ones (docs/basis_study.md)
              "l2": 1e-3, "ensemble": 5},
    # Any liver in real time (surrogate/population_basis.py): modes over the population's
    # fields on the registered template; the network also sees the shape coefficients.
    "population_basis": {"design": "population_basis", "modes": 64, "hidden": [256, 256],
                         "batch_size": 128, "epochs": 400, "early_stopping": 30,
                         "lr_patience": 8, "folds": 8,
                         # regularised: without it the net learns the training livers by
                         # their shape coefficients (docs/population_basis.md); light input
                         # noise with weight decay, chosen at 16 simulations per liver and
                         # confirmed at 8 (docs/livers_or_loads.md)
                         "input_noise": 0.1, "l2": 1e-2,
                         # each field's RMS error, not its square: lower on real livers held
                         # out, liver by liver and fold by fold (docs/real_knobs.md)
                         "loss": "rms",
                         # where each load sits relative to the fixed region and on the
                         # template: the knob that matters most (docs/population_basis.md)
                         "load_context": True,
                         # five networks averaged: a lower MEE on held-out livers for a
                         # slightly slower call (docs/population_basis.md)
                         "ensemble": 5},
}
# Scene 4 over each liver's own small-strain base (fem_sim linear --population --order 2): the
# population basis learns only what the base misses (the stiffening beyond second order), and
# a prediction adds the base of the liver's own mesh (docs/scene4_real.md).
CONFIGS["population_linear"] = {**CONFIGS["population_basis"], "linear_base": 2}
# The same over each liver's linear response alone (order 1): linear in the force, so the
# liver's Green's function (fem_sim linear --green: one factorisation) gives the base of any
# nodal load at run time, and a new liver gets whole fields without an FE simulation or a
# training (make liver, surrogate/over_green.py; docs/scene4_real.md).
CONFIGS["population_green"] = {**CONFIGS["population_basis"], "linear_base": 1}


# key -> (check, what is expected): every value is checked before training starts.
CHECKS = {
    "modes": (lambda v: is_int(v) and v >= 1, "an integer >= 1"),
    "hidden": (lambda v: isinstance(v, list) and v and all(is_int(w) and w > 0 for w in v),
               "a non-empty list of layer widths > 0"),
    "dropout": (lambda v: is_num(v) and 0 <= v < 1, "a number in [0, 1)"),
    "loss": (lambda v: v in ("mse", "rms", "mee"), "'mse', 'rms' or 'mee'"),
    "l2": (lambda v: is_num(v) and v >= 0, "a finite number >= 0"),
    "input_noise": (lambda v: is_num(v) and v >= 0, "a finite number >= 0"),
    "shape_noise": (lambda v: v is None or is_num(v) and v >= 0,
                    "null or a finite number >= 0"),
    "load_context": (lambda v: isinstance(v, bool), "true or false"),
    "shared_loads": (lambda v: isinstance(v, bool), "true or false"),
    "linear_base": (lambda v: v in BASES and not isinstance(v, bool),
                    ", ".join(f"{k} ({b.name})" for k, b in BASES.items())),
    "ensemble": (lambda v: is_int(v) and v >= 1, "an integer >= 1"),
    "shape_inputs": (lambda v: v == "all" or is_int(v) and v >= 0, "'all' or an integer >= 0"),
    "batch_size": (lambda v: is_int(v) and v >= 1, "an integer >= 1"),
    "learning_rate": (lambda v: is_num(v) and v > 0, "a finite number > 0"),
    "lr_rule": (lambda v: v in ("plateau", "decay"), "'plateau' or 'decay'"),
    "lr_patience": (lambda v: is_int(v) and v >= 1, "an integer >= 1"),
    "epochs": (lambda v: is_int(v) and v >= 1, "an integer >= 1"),
    "early_stopping": (lambda v: is_int(v) and v >= 1, "an integer >= 1"),
    "node_fraction": (lambda v: is_num(v) and 0 < v <= 1, "a number in (0, 1]"),
    "inner_val_fraction": (lambda v: is_num(v) and 0 <= v < 1, "a number in [0, 1)"),
    "folds": (lambda v: is_int(v) and v >= 2, "an integer >= 2 (k-fold cross-validation)"),
    "evaluate_folds": (lambda v: is_int(v) and v >= 0, "an integer >= 0 (0: every fold)"),
    "final_fit": (lambda v: isinstance(v, bool), "true or false"),
    "phantoms_in_training": (lambda v: isinstance(v, bool), "true or false"),
    "train_fraction": (lambda v: is_num(v) and 0 < v <= 1, "a number in (0, 1]"),
    "simulations_per_liver": (lambda v: is_int(v) and v >= 0, "an integer >= 0 (0: all)"),
    "seed": (lambda v: is_int(v) and v >= 0, "an integer >= 0"),
    "dtype": (lambda v: v == "float32", "'float32' (the only training precision)"),
    "stream": (lambda v: v in (True, False, "auto"), "true, false or 'auto'"),
}


def design_problems(cfg: dict) -> list[str]:
    """The config's design is one of the registry's, and a design-specific key that its design
    does not read (``takes``) keeps the base value.
    """
    from surrogate.designs import DESIGNS

    design = DESIGNS.get(cfg["design"])
    if design is None:
        return [f"design: expected {' or '.join(map(repr, DESIGNS))}, got {cfg['design']!r}"]
    specific = set().union(*(d.takes for d in DESIGNS.values()))
    out = []
    for key in sorted(specific - design.takes):
        if cfg[key] != BASE[key]:
            takers = " and ".join(n for n, d in DESIGNS.items() if key in d.takes)
            out.append(f"{key}: the {design.name} design does not take it, only {takers} "
                       f"(expected {BASE[key]!r}, got {cfg[key]!r})")
    return out


def get_config(name: str = "small", **overrides) -> dict:
    """A copy of config ``name`` with ``overrides`` applied. ValueError listing every problem:
    an unknown name or key, or a value out of its range.
    """
    if name not in CONFIGS:
        raise ValueError(f"unknown trainer config {name!r}; expected one of {sorted(CONFIGS)}")
    cfg = copy.deepcopy(BASE)
    cfg.update(copy.deepcopy(CONFIGS[name]))
    problems = [f"unknown config key {k!r}; expected one of {sorted(BASE)}"
                for k in overrides if k not in BASE]
    cfg.update({k: v for k, v in overrides.items() if k in BASE})
    problems += [f"{k}: expected {what}, got {cfg[k]!r}" for k, (ok, what) in CHECKS.items()
                 if not ok(cfg[k])]
    problems += design_problems(cfg)
    if problems:
        raise ValueError("trainer config: " + "; ".join(problems))
    cfg["name"] = name
    return cfg
