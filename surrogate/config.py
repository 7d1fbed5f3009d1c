"""Trainer configurations: plain dicts, ``get_config(name)`` plus overrides (Flax-examples style).

The paper's Table 3 architectures: scene 1 (500, 300, 100, 50); scenes 2-3 deeper variants;
scene 4 five layers of 500. "small" is the CI/demo size.
"""

from __future__ import annotations

import copy

BASE = {
    "hidden": [128, 128, 128],
    "dropout": 0.0,
    "l2": 0.0,                 # weight decay coefficient (added to the loss as l2 * |w|^2 / 2)
    "input_noise": 0.0,        # std of Gaussian noise on normalised inputs during training
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
    "final_fit": True,         # train the exported model on all simulations after CV
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
}


def get_config(name: str = "small", **overrides) -> dict:
    """A copy of config ``name`` with ``overrides`` applied. Unknown names/keys raise."""
    if name not in CONFIGS:
        raise KeyError(f"unknown trainer config {name!r}; expected one of {sorted(CONFIGS)}")
    cfg = copy.deepcopy(BASE)
    cfg.update(copy.deepcopy(CONFIGS[name]))
    unknown = set(overrides) - set(BASE)
    if unknown:
        raise KeyError(f"unknown config keys {sorted(unknown)}; expected some of {sorted(BASE)}")
    cfg.update(overrides)
    cfg["name"] = name
    return cfg
