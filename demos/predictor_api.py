"""The trainer and the exported model from Python (the trainer environment, no dolfinx).

    .venv-train/bin/python demos/predictor_api.py DATASET [RUN]

Trains a small network on a dataset fem_sim generated (one liver, one force), then loads the
exported model as a user's program does and predicts: the whole liver, the surface only, many
load cases in one call.
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

from surrogate import load_predictor
from surrogate.config import get_config
from surrogate.train import train_and_evaluate

data = Path(sys.argv[1])
run = Path(sys.argv[2]) if len(sys.argv) > 2 else Path(tempfile.mkdtemp()) / "run"
cfg = get_config("small", folds=2, epochs=5)              # a named config plus overrides
result = train_and_evaluate(data, run, cfg, log_fn=lambda line: None)
print(f"cross-validated skill {result['skill']:.3f} (MEE {result['network']['mee']:.3f} mm)")

predict = load_predictor(run / "model")                   # plain files: no pickle, no code
node = int(predict.loadable[0])                           # a node the scene loads
u = predict(forces=[[0.0, 0.0, -0.4]], load_nodes=[node])            # (n_nodes, 3) mm
surface = np.unique(predict.triangles)
u_surf = predict([[0.0, 0.0, -0.4]], [node], nodes=surface)          # the surface only
many = predict(np.tile([[[0.0, 0.0, -0.4]]], (8, 1, 1)) * np.linspace(0.1, 1.0, 8)[:, None,
                                                                                     None],
               np.full((8, 1), node))                                # (8, n_nodes, 3)
assert np.allclose(u_surf, u[surface], atol=1e-4)
assert np.allclose(many[-1], u, atol=1e-4)
print(f"{u.shape[0]} nodes, max |u| {np.linalg.norm(u, axis=1).max():.2f} mm; "
      f"{surface.size} surface nodes; 8 cases in one call")
