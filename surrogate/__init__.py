"""surrogate: JAX/Flax node-wise displacement surrogate (never imports dolfinx).

from surrogate import load_predictor
predict = load_predictor("runs/train/demo_scene1/model")
u = predict(forces=[[0, 0, -0.4]], load_nodes=[123])     # (n_nodes, 3) mm
"""


def load_predictor(directory, dtype: str = "float32", load: str = "nodal"):
    """Load an exported model directory; returns a jitted :class:`surrogate.predictor.Predictor`
    (``dtype`` "bfloat16" or "float16": the network in 16 bits; ``load`` "grasp" for a model
    of grasps, whose loads are tools' pulls in mm).
    """
    from surrogate.predictor import load_predictor as _load

    return _load(directory, dtype, load)


__all__ = ["load_predictor"]
