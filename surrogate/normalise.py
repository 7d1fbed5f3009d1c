"""Normalisation of features and targets: pure functions of stored statistics.

A :class:`Normaliser` is a pytree (it travels through ``jit`` with the parameters) and is the
one definition used by training, evaluation and the exported predictor. Its statistics are
checked when they are built or loaded: finite means, positive finite scales, the right sizes.
"""

from __future__ import annotations

import numpy as np
from flax import struct

KEYS = ("x_mean", "x_std", "y_mean", "y_std")


@struct.dataclass
class Normaliser:
    """Means and scales of the features and of the displacements (mm)."""

    x_mean: np.ndarray  # (dim,) feature means
    x_std: np.ndarray   # (dim,) feature scales (1 for constant features)
    y_mean: np.ndarray  # (3,) displacement mean, mm
    y_std: np.ndarray   # (3,) displacement scale, mm

    @classmethod
    def fit(cls, x: np.ndarray, y: np.ndarray) -> Normaliser:
        """Statistics of features ``x`` (n, dim) and targets ``y`` (n, 3). A feature that does
        not vary (relative spread < 1e-8) keeps scale 1 instead of dividing by ~0.
        """
        std = x.std(axis=0)
        return cls(x_mean=x.mean(axis=0).astype(np.float32),
                   x_std=np.where(std > 1e-8 * (np.abs(x).max(axis=0) + 1e-30), std, 1.0)
                   .astype(np.float32),
                   y_mean=y.mean(axis=0).astype(np.float32),
                   y_std=np.maximum(y.std(axis=0), 1e-12).astype(np.float32))

    def inputs(self, x):
        return (x - self.x_mean) / self.x_std

    def targets(self, y):
        return (y - self.y_mean) / self.y_std

    def outputs(self, y_normalised):
        """Network outputs back to millimetres."""
        return y_normalised * self.y_std + self.y_mean

    def to_dict(self) -> dict:
        return {k: np.asarray(getattr(self, k)).tolist() for k in KEYS}

    @classmethod
    def from_dict(cls, d, dim: int, where: str = "stats") -> Normaliser:
        """Checked statistics; ValueError naming ``where`` and the key on any problem."""
        if not isinstance(d, dict):
            raise ValueError(f"{where}: expected an object with {', '.join(KEYS)}")
        sizes = {"x_mean": dim, "x_std": dim, "y_mean": 3, "y_std": 3}
        out = {}
        for k in KEYS:
            try:
                a = np.asarray(d[k], dtype=np.float32)
            except KeyError:
                raise ValueError(f"{where}.{k}: missing") from None
            except (TypeError, ValueError):
                raise ValueError(f"{where}.{k}: expected a list of numbers") from None
            if a.shape != (sizes[k],):
                raise ValueError(f"{where}.{k}: expected {sizes[k]} values, got shape {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{where}.{k}: contains NaN or inf")
            if k.endswith("std") and not np.all(a > 0):
                raise ValueError(f"{where}.{k}: scales must be > 0, got {a.tolist()}")
            out[k] = a
        return cls(**out)
