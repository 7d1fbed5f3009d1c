"""The node-wise MLP: normalised features (dim,) -> normalised displacement (3,).

Dense layers act on the last axis, so the same module maps one node or a batch of nodes. The
layers are named ``hidden_0`` ... ``hidden_{n-1}`` and ``output``: the names of the exported
parameters (``params.npz``), independent of flax's automatic naming.
"""

from __future__ import annotations

from collections.abc import Sequence

import flax.linen as nn


class NodeMLP(nn.Module):
    """ReLU MLP with optional dropout; hidden widths from the config, 3 outputs."""

    hidden: Sequence[int]
    dropout: float = 0.0

    @nn.compact
    def __call__(self, x, *, train: bool = False):
        for i, width in enumerate(self.hidden):
            x = nn.relu(nn.Dense(width, name=f"hidden_{i}")(x))
            if self.dropout > 0:
                x = nn.Dropout(self.dropout, deterministic=not train)(x)
        return nn.Dense(3, name="output")(x)
