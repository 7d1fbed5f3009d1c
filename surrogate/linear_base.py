"""The patient's small-strain responses (``fem_sim linear``, :mod:`data_spec.linear_fields`)
as what a patient model starts from: the exact linear elasticity of the patient's own mesh
with the model's boundary condition, for the loads of its FE simulations and for drawn loads
of the same rule. A linear response scales with the load fraction, so a case at fraction
``lam`` is ``lam`` times its response at fraction 1; a file of order 2 (``fem_sim linear
--order 2``) adds ``lam**2`` times the second-order term, the law's first stiffening. At the
loads of a patient's scene the truncated series is far from converged, but its two terms
still span most of the FE field: fitted on the patient's FE simulations (:meth:`LinearBase.fit`),
each load fraction weighs them by the median over the simulations of their least-squares
weights (docs/load_expansion.md measures both). What the nonlinear FE simulations add beyond
that is corrected by :mod:`surrogate.patient`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from data_spec.linear_fields import linear_fields_path, read_linear_fields
from surrogate.data import Dataset


class LinearBase:
    """The responses of ``path`` (default ``ds.directory/linear.h5``) at the output nodes of
    the one-liver dataset ``ds``.
    """

    def __init__(self, ds: Dataset, path: str | Path | None = None):
        path = Path(path) if path else linear_fields_path(ds.directory)
        self.path, self.lf = path, read_linear_fields(path)
        out = np.asarray(ds.out_nodes[0])
        have = self.lf.output_nodes
        where = np.searchsorted(have, out)
        if np.any(where >= have.size) or np.any(have[np.minimum(where, have.size - 1)] != out):
            raise ValueError(f"{path}: its output nodes are not the dataset's "
                             f"({ds.directory}): rerun fem_sim linear on the dataset's scene")
        self.columns = where
        self.fractions = np.unique(np.round(ds.sample_fraction, 9))
        # the terms' weights relative to the series (lam, lam^2) by load fraction: fitted
        self.weights: tuple | None = None   # (fractions (F,), weights (F, 2)), or None

    @classmethod
    def of(cls, ds: Dataset) -> LinearBase | None:
        """The dataset's responses, None when it has no linear.h5."""
        if ds.directory is None or not linear_fields_path(ds.directory).exists():
            return None
        return cls(ds)

    def samples(self, ds: Dataset, samples: np.ndarray) -> np.ndarray:
        """(samples, n_out, 3) mm: the responses of the samples' simulations at their load
        fractions.
        """
        rows = self.lf.rows(ds.sample_sim[samples])
        return self._at(rows, np.asarray(ds.sample_fraction[samples], np.float64))

    @property
    def order(self) -> int:
        return self.lf.order

    def _at(self, rows: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """(len(rows), n_out, 3) mm: the responses of the file's ``rows`` at fractions ``lam``,
        to the file's order.
        """
        w = self.weights_at(lam)
        u = self.lf.displacement[rows][:, self.columns].astype(np.float64)
        u *= (lam * w[:, 0])[:, None, None]
        if self.lf.second_order is not None:
            u += self.lf.second_order[rows][:, self.columns] * (lam**2 * w[:, 1])[:, None, None]
        return u

    def weights_at(self, lam: np.ndarray) -> np.ndarray:
        """(len(lam), 2): the terms' weights relative to the series, (1, 1) until fitted;
        between fitted fractions interpolated, from (1, 1) at lam = 0 (where the series is
        exact).
        """
        lam = np.asarray(lam, np.float64)
        if self.weights is None:
            return np.ones((lam.size, 2))
        at, w = self.weights
        return np.column_stack([np.interp(lam, np.r_[0.0, at], np.r_[1.0, w[:, i]])
                                for i in range(2)])

    def fit(self, ds: Dataset, samples: np.ndarray, fields: np.ndarray) -> None:
        """The terms' weights from the FE ``fields`` (samples, n_out, 3) mm of the patient's
        ``samples``: for each sample the least-squares weights of lam u1 and lam^2 u2 on its
        field, then by load fraction the median over the samples (robust to a simulation
        whose load sits where the series fails worst). Nothing to fit at order 1: one
        scale of the linear response, fitted so, was measured not to help.
        """
        if self.lf.second_order is None or not len(samples):
            return
        rows = self.lf.rows(ds.sample_sim[samples])
        lam = np.asarray(ds.sample_fraction[samples], np.float64)
        u1 = self.lf.displacement[rows][:, self.columns].astype(np.float64)
        u2 = self.lf.second_order[rows][:, self.columns].astype(np.float64)
        w = np.array([np.linalg.lstsq(np.column_stack([a.ravel() * x, b.ravel() * x**2]),
                                      d.ravel(), rcond=None)[0]
                      for a, b, d, x in zip(u1, u2, np.asarray(fields, np.float64), lam)])
        at = np.unique(np.round(lam, 9))
        self.weights = (at, np.array([np.median(w[np.isclose(lam, x)], axis=0) for x in at]))

    def drawn(self, n: int) -> tuple:
        """(forces (S, 3) N, load nodes (S,), fractions (S,), case (S,), fields (S, n_out, 3)
        mm): the file's first ``n`` drawn cases, each at every load fraction of the dataset;
        ValueError when the file has fewer.
        """
        rows = self.lf.synthetic[:n]
        if rows.size < n:
            raise ValueError(f"{self.path}: {rows.size} drawn cases, fewer than the {n} asked: "
                             f"rerun fem_sim linear with --synthetic {n}")
        if self.lf.load_nodes.shape[1] != 1:
            raise ValueError(f"{self.path}: {self.lf.load_nodes.shape[1]} loads per case; a "
                             "patient model is of one load")
        rep = self.fractions.size
        lam = np.tile(self.fractions, n)
        forces = np.repeat(self.lf.forces[rows, 0], rep, axis=0) * lam[:, None]
        return (forces, np.repeat(self.lf.load_nodes[rows, 0], rep), lam,
                np.repeat(np.arange(n), rep), self._at(np.repeat(rows, rep), lam))
