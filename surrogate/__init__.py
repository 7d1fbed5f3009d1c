"""surrogate: JAX/Flax node-wise displacement surrogate (never imports dolfinx)."""
