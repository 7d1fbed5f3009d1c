"""The patient's small-strain responses (``fem_sim linear``, :mod:`data_spec.linear_fields`)
as what a patient model starts from: the exact linear elasticity of the patient's own mesh
with the model's boundary condition, for the loads of its FE simulations and for drawn loads
of the same rule. A linear response scales with the load fraction, so a case at fraction
``lam`` is ``lam`` times its response at fraction 1; a file of order 2 (``fem_sim linear
--order 2``) adds the second-order term, the law's first stiffening, damped and gated by the
response's own ratio of terms (:meth:`LinearBase.terms`; docs/load_expansion.md measures the
choices on training livers). What the nonlinear FE simulations add beyond that is corrected
by :mod:`surrogate.patient`.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from data_spec.linear_fields import linear_fields_path, read_dataset_linear, read_linear_fields
from surrogate.data import Dataset
from surrogate.small_strain import green_product

R_MAX = 1.0   # a load's second term is kept while |u2| / |u1| is below this


def _ratio(lf) -> np.ndarray:
    """(n,): |u2| / |u1| of each response of the file (root of the sums of squares over its
    output nodes; zero at order 1).
    """
    if lf.second_order is None:
        return np.zeros(lf.case_index.size)
    one = np.sqrt((lf.displacement.astype(np.float64) ** 2).sum(axis=(1, 2)))
    two = np.sqrt((lf.second_order.astype(np.float64) ** 2).sum(axis=(1, 2)))
    return two / np.maximum(one, 1e-300)


def series_terms(u1, u2, ratio, lam) -> tuple:
    """The base's two terms of responses ``u1`` (and second-order terms ``u2``, or None), each
    (n, n_out, 3), at fractions ``lam`` (n,): lam u1, and lam^2 u2 / (1 + lam R) with R =
    ``ratio`` = |u2| / |u1| (the response's own ratio, over its output nodes): the series'
    second term, damped as the [1/1] rational form of a series of that ratio would, and zero
    where R >= R_MAX (a load whose second term outgrows its first: the series is no guide
    there, the linear response alone is kept). At order 1 the second term is zero.
    """
    lam = np.asarray(lam, np.float64)
    one = np.asarray(u1, np.float64) * lam[:, None, None]
    if u2 is None:
        return one, np.zeros_like(one)
    r = np.asarray(ratio, np.float64)
    damp = np.where(r < R_MAX, lam**2 / (1.0 + lam * r), 0.0)
    return one, np.asarray(u2, np.float64) * damp[:, None, None]


class LinearBase:
    """The responses of ``path`` (default ``ds.directory/linear.h5``) at the output nodes of
    the one-liver dataset ``ds``.
    """

    def __init__(self, ds: Dataset, path: str | Path | None = None):
        self.path = Path(path) if path else linear_fields_path(ds.directory)
        self.lf = read_linear_fields(path) if path else read_dataset_linear(ds.directory)
        out = np.asarray(ds.out_nodes[0])
        have = self.lf.output_nodes
        where = np.searchsorted(have, out)
        if np.any(where >= have.size) or np.any(have[np.minimum(where, have.size - 1)] != out):
            raise ValueError(f"{path}: its output nodes are not the dataset's "
                             f"({ds.directory}): rerun fem_sim linear on the dataset's scene")
        self.columns = where
        self.fractions = np.unique(np.round(ds.sample_fraction, 9))
        self.ratio = _ratio(self.lf)

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

    @functools.cached_property
    def green(self) -> tuple | None:
        """(nodes (n_g,), (n_g, 3, n_out, 3) mm/N at the dataset's output nodes): the file's
        Green's function (``fem_sim linear --green``), None without it.
        """
        if self.lf.green is None:
            return None
        return self.lf.green_nodes, self.lf.green[:, :, self.columns]

    def green_part(self, load_nodes, forces) -> np.ndarray:
        """(S, n_out, 3) mm: the exact small-strain response of one nodal load per case
        (load nodes (S,), forces (S, 3) N) from the Green's function; ValueError naming the
        nodes it does not hold.
        """
        nodes, g = self.green
        load_nodes = np.asarray(load_nodes).ravel()
        at = np.minimum(np.searchsorted(nodes, load_nodes), nodes.size - 1)
        if np.any(nodes[at] != load_nodes):
            raise ValueError(f"{self.path}: no unit response at node(s) "
                             f"{load_nodes[nodes[at] != load_nodes][:5].tolist()}")
        return green_product(g, at[:, None], np.asarray(forces, np.float64).reshape(-1, 1, 3))

    def terms(self, rows: np.ndarray, lam: np.ndarray) -> tuple:
        """The base's two terms for the file's ``rows`` at fractions ``lam``, each
        (len(rows), n_out, 3) mm (:func:`series_terms`).
        """
        u = self.lf.displacement[rows][:, self.columns]
        two = None if self.lf.second_order is None else \
            self.lf.second_order[rows][:, self.columns]
        return series_terms(u, two, self.ratio[rows], lam)

    def _at(self, rows: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """(len(rows), n_out, 3) mm: the base for the file's ``rows`` at fractions ``lam``."""
        one, two = self.terms(rows, lam)
        return one + two

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


def case_base(lf, order: int, case: int, lam, ratio: np.ndarray | None = None) -> np.ndarray:
    """(len(lam), n_out, 3) mm: the series of file ``lf``'s response to ``case`` to ``order``
    (1 or 2) at the fractions ``lam``, at the file's output nodes (``ratio``: the file's
    |u2| / |u1| per row when the caller keeps it).
    """
    r = int(lf.rows([case])[0])
    if order > lf.order:
        raise ValueError(f"liver {lf.geometry_id}: responses of order {lf.order}, {order} "
                         "asked: rerun fem_sim linear with --order 2")
    lam = np.asarray(lam, np.float64)
    n = lam.size
    ratio = _ratio(lf) if ratio is None else ratio
    one, two = series_terms(np.repeat(lf.displacement[r:r + 1], n, axis=0),
                            None if order == 1 else np.repeat(lf.second_order[r:r + 1], n, 0),
                            np.full(n, ratio[r]), lam)
    return one + two


class PopulationLinearBase:
    """The small-strain responses of every liver of a population dataset (``fem_sim linear
    --population``: ``DATA/linear/<geometry id>.h5``), at each liver's output nodes: the base
    a population model may learn the rest of (config ``linear_base``: the series to that
    order).
    """

    def __init__(self, ds: Dataset, order: int = 2):
        self.files, self.order = {}, int(order)
        for g, gid in enumerate(ds.geo_ids):
            path = linear_fields_path(ds.directory, gid)
            if not path.exists():
                raise ValueError(f"{path}: no small-strain responses of liver {gid}: run "
                                 f"`fem_sim linear --population {ds.directory} --order 2`")
            lf = read_dataset_linear(ds.directory, gid)
            if not np.array_equal(lf.output_nodes, np.asarray(ds.out_nodes[g])):
                raise ValueError(f"{path}: its output nodes are not the dataset's liver {gid}'s: "
                                 "rerun fem_sim linear --population")
            if lf.order < self.order:
                raise ValueError(f"{path}: responses of order {lf.order}, the config's "
                                 f"linear_base asks {self.order}: rerun fem_sim linear "
                                 "--population --order 2")
            self.files[g] = (lf, _ratio(lf))   # the ratio once per liver, not per sample

    def sample(self, ds: Dataset, s: int) -> np.ndarray:
        """(n_out, 3) mm: sample ``s``'s base on its own liver's output nodes."""
        lf, ratio = self.files[int(ds.sample_geo[s])]
        return case_base(lf, self.order, int(ds.sample_sim[s]), [ds.sample_fraction[s]],
                         ratio)[0]


def liver_base_metrics(data: str | Path, order: int = 2) -> dict:
    """The small-strain base alone against the FE fields of a one-liver dataset ``data``
    (its ``linear.h5``): the displacement metrics over every done load step.
    """
    from data_spec.shards import list_shards, read_shard
    from surrogate.metrics import displacement_metrics

    lf = read_dataset_linear(data)
    P, T = [], []
    for sh in (s for s in map(read_shard, list_shards(data)) if s.n_done):
        fr = np.asarray(sh.load_fractions[:sh.n_done])
        P.append(case_base(lf, order, sh.sim_index, fr).reshape(-1, 3))
        T.append(np.asarray(sh.displacement[:sh.n_done]).reshape(-1, 3))
    return displacement_metrics(np.concatenate(P), np.concatenate(T))
