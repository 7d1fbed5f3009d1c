"""The reduced basis over a population of livers (``design = "population_basis"``).

Every liver of a scene-4 population carries the template's nodes once the template is
registered onto it (:func:`surrogate.population.registered_templates`): each simulation's
field, interpolated from the liver's own nodes to the registered template's, lives in one node
order for the whole population. The modes are the leading singular vectors of those fields,
and the network of :mod:`surrogate.basis` maps the loads (load point, force direction and
magnitude), the shape coefficients (and the material where the scene varies it) to their
coefficients. A call costs one small network and one (3 n_template x modes) product, for any
liver: the registered template is the new liver's mesh (``predict-liver``).

Each load is also described by where it sits on the liver, in terms every liver shares
(:func:`load_context`, ``load_context = true``): its place on the template (the same anatomical
point on every liver, whatever the liver's shape), its offset from the fixed region's centroid
and its distance to the fixed region (what the response depends on most). Training reads them
through each liver's registered template; a prediction, from the load's template node.

Metrics are taken on each liver's own nodes (the predicted template field interpolated back),
so they compare with the node-wise design's on the same held-out livers.
"""

from __future__ import annotations

import weakref

import numpy as np

from liverreg.morph import interpolation_matrix
from surrogate.basis import (
    Basis,
    BasisDesignError,
    BasisModel,
    BasisProblem,
    BasisRuntime,
    predict_fields,
)
from surrogate.data import Dataset

CONTEXT = 7  # per load: place on the template (3), offset from the fixed centroid (3), distance


def load_context(load_points, anatomical, fixed_points) -> np.ndarray:
    """(..., n_loads, 7) context of loads on one liver: ``anatomical`` (..., n_loads, 3), the
    template's coordinates of the points under them; their offset from the centroid of
    ``fixed_points`` (n_fixed, 3) and their distance to the nearest of those points, mm.
    """
    P = np.asarray(load_points, dtype=np.float64)
    F = np.asarray(fixed_points, dtype=np.float64)
    d2 = ((P[..., None, :] - F) ** 2).sum(axis=-1).min(axis=-1)
    return np.concatenate([np.asarray(anatomical, dtype=np.float64), P - F.mean(axis=0),
                           np.sqrt(d2)[..., None]], axis=-1)


class TemplateFields:
    """A population dataset's fields in the template's node order, and back to each liver's
    own output nodes (linear interpolation both ways).
    """

    def __init__(self, ds: Dataset):
        from surrogate.population import population_file, registered_templates, template_geometry

        if not ds.spec.geometry_dim:
            raise BasisDesignError("design 'population_basis' needs a scene that varies the "
                                   "liver (a population); one liver takes design 'basis'")
        pop = population_file(ds.directory) if ds.directory is not None else None
        if pop is None or not pop.exists():
            raise BasisDesignError(f"design 'population_basis' needs the population's "
                                   f"registration ({pop or 'the dataset has no directory'}); "
                                   "generate the dataset with fem_sim, which writes it")
        reg = registered_templates(ds.directory)
        missing = [g for g in ds.geo_ids if g not in reg]
        if missing:
            raise BasisDesignError(f"livers {missing[:3]} are not in the population file "
                                   f"{pop}")
        # every sample's load context too: each liver's loads through its registered template
        # (one interpolation from it per liver, to its output nodes and its load points)
        template = template_geometry(ds.directory).points
        self.context = np.zeros(ds.load_points.shape[:2] + (CONTEXT,), dtype=np.float32)
        self.to_template, self.to_liver = [], []
        for g, gid in enumerate(ds.geo_ids):
            own = ds.points[g][ds.out_nodes[g]]
            sel = np.flatnonzero(ds.sample_geo == g)
            P = np.asarray(ds.load_points[sel], dtype=np.float64)
            W = interpolation_matrix(reg[gid], np.vstack([own, P.reshape(-1, 3)]))
            self.to_template.append(interpolation_matrix(own, reg[gid]))
            self.to_liver.append(W[:len(own)])
            anatomical = (W[len(own):] @ template).reshape(P.shape)
            self.context[sel] = load_context(P, anatomical, ds.points[g][ds.fixed[g]])
        self.n_template = next(iter(reg.values())).shape[0]

    def fields(self, ds: Dataset, samples: np.ndarray, base=None) -> np.ndarray:
        """(len(samples), 3 n_template) fields of samples on the registered template; less
        each sample's small-strain base on its liver's nodes when ``base`` (a
        :class:`~surrogate.linear_base.PopulationLinearBase`) is given.
        """
        out = np.empty((len(samples), 3 * self.n_template))
        for i, s in enumerate(samples):
            u = np.asarray(ds.targets[ds.sample_offset[s]:ds.sample_offset[s + 1]],
                           dtype=np.float64)
            if base is not None:
                u = u - base.sample(ds, s)
            out[i] = (self.to_template[ds.sample_geo[s]] @ u).ravel()
        return out


class PopulationBasisRuntime(BasisRuntime):
    """An exported population basis at prediction time: the reduced basis' call on the
    registered template (a liver is placed on it by :mod:`surrogate.predict_liver`), with the
    loads' context on the liver predicted on when the model reads one.
    """

    outputs_only = False  # the template's every node is an output node
    contexts = (0, CONTEXT)

    def check_geometry(self, pred, geometry) -> None:
        """A registered template of any liver."""

    def check_points(self, pred, n_nodes: int) -> None:
        if n_nodes != pred.output_nodes.size:
            raise ValueError(f"geometry: a population-basis model predicts on the registered "
                             f"template ({pred.output_nodes.size} nodes; "
                             "surrogate.predict_liver places a liver), got {n_nodes} points")

    def context(self, pred, load_nodes, liver):
        """(n_cases, n_loads, c) the loads' context on the liver predicted on (``liver``:
        (key, points, fixed nodes), None for the template itself); a load node of the
        registered template is the template's node of the same id. Kept once per (liver,
        load nodes): a manipulator drags one node with changing forces.
        """
        import jax.numpy as jnp

        if not self.stats.context:
            return super().context(pred, load_nodes, liver)
        key = (None if liver is None else liver[0], load_nodes.dtype.str, load_nodes.shape,
               load_nodes.tobytes())
        if getattr(self, "_ctx_key", None) != key:
            points, fixed = (pred.points, pred.fixed) if liver is None else liver[1:]
            self._ctx_key = key
            self._ctx = jnp.asarray(load_context(points[load_nodes], pred.points[load_nodes],
                                                 points[fixed]), dtype=jnp.float32)
        return self._ctx


class PerDataset:
    """Values computed once per dataset and dropped with it: kept by the object that computes
    them, not as attributes put on the dataset (a Dataset is not hashable: keyed by its id,
    with a finalizer that drops the entry when the dataset goes).
    """

    def __init__(self):
        self._values: dict = {}

    def get(self, ds: Dataset, key, make):
        """The value of ``key`` for ``ds``, ``make()`` the first time."""
        k = (id(ds), key)
        if k not in self._values:
            self._values[k] = make()
            weakref.finalize(ds, self._values.pop, k, None)
        return self._values[k]


class PopulationBasis(Basis):
    """The design's entry in the registry (:data:`surrogate.designs.DESIGNS`); the model and
    its export are the reduced basis' (modes on the template's nodes).
    """

    name = "population_basis"
    label = "population basis"
    log_every = 10
    # the shape it is told for a liver outside its population (ShapeModel.shape_told): the
    # shape coefficients are all it knows of the liver's shape: the nearest mix of the
    # population's livers for any liver outside it (chosen on phantoms drawn beyond the
    # population, docs/shape_rule.md)
    shape_rule = "outside"
    on_template = True  # its modes, and the liver it is exported with, are the template's
    takes = Basis.takes | {"shape_inputs", "load_context", "shape_noise", "linear_base"}

    def __init__(self):
        self._per_dataset = PerDataset()   # each dataset's template fields and bases

    def scene_problem(self, varies_geometry: bool) -> str | None:
        """Why a scene cannot take the design (None when it can)."""
        if not varies_geometry:
            return (f"design {self.name!r} needs a population of livers; the scene has one "
                    "liver: use config 'basis'")
        return None

    def runtime(self, d, pred, hidden: tuple, dropout: float,
                dtype: str) -> PopulationBasisRuntime:
        """The exported model in ``d`` at prediction time."""
        return PopulationBasisRuntime(d, pred, hidden, dropout, dtype)

    def maps(self, ds: Dataset) -> TemplateFields:
        """The dataset's TemplateFields, built once and kept with the dataset (so they live
        and die with it).
        """
        return self._per_dataset.get(ds, "maps", lambda: TemplateFields(ds))

    def base(self, ds: Dataset, cfg: dict):
        """The dataset's small-strain base when the config learns the rest of it (kept with
        the dataset), else None.
        """
        from surrogate.linear_base import PopulationLinearBase
        from surrogate.small_strain import base_of

        kind = base_of(cfg.get("linear_base", 0))
        if kind.whole:
            return None
        return self._per_dataset.get(ds, ("base", kind.order),
                                     lambda: PopulationLinearBase(ds, kind.order))

    def check(self, ds: Dataset, cfg: dict | None = None) -> None:
        self.maps(ds)
        if cfg is not None:
            self.base(ds, cfg)

    def problem(self, ds, train, val, cfg, rng) -> BasisProblem:
        maps, base = self.maps(ds), self.base(ds, cfg)
        return BasisProblem(ds, train, val, cfg, int(rng.integers(2**31)),
                            fields_of=lambda s: maps.fields(ds, s, base),
                            context=maps.context if cfg["load_context"] else None)

    def summary(self, problem: BasisProblem) -> str:
        return (f"{problem.modes.shape[0]} modes over the population, projection MEE of the "
                f"training fields on the template {problem.projection_mee:.4f} mm")

    def predict_samples(self, ds: Dataset, model: BasisModel, cfg: dict, samples: np.ndarray):
        """Predicted and true displacement on each sample's own liver nodes."""
        maps, base = self.maps(ds), self.base(ds, cfg)
        U = predict_fields(ds, model, samples, maps.context if model.context else None)
        pred = [maps.to_liver[ds.sample_geo[s]] @ u.reshape(-1, 3)
                + (0.0 if base is None else base.sample(ds, s)) for s, u in zip(samples, U)]
        true = [ds.targets[ds.sample_offset[s]:ds.sample_offset[s + 1]] for s in samples]
        rows = [np.full(len(t), s) for s, t in zip(samples, true)]
        return (np.concatenate(pred).astype(np.float32),
                np.asarray(np.concatenate(true), dtype=np.float32), np.concatenate(rows))
