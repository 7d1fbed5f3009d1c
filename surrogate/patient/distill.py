"""The distillation of a patient's teacher (:mod:`surrogate.patient`): loads drawn as the
patient's scene draws them, their fields from the teacher, and the reduced basis trained on
them with the K FE fields (over the liver's Green's function when it has one).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from surrogate.data import Dataset
from surrogate.patient.teacher import Teacher, sims_samples

# the distilled model's config (its RMS loss as the population basis's: docs/real_knobs.md),
# and the drawn loads it learns the corrected model from beside the K FE simulations
# (docs/patient.md: the student's settings, measured on training livers)
STUDENT = {"design": "basis", "ensemble": 1, "folds": 2, "loss": "rms"}
SYNTHETIC = 600


def drawn_loads(ds: Dataset, n_sims: int, seed: int):
    """(forces (S, 3) N, load nodes (S,), fractions (S,), simulation (S,)): ``n_sims`` loads
    drawn as the patient's scene draws them (a node it may load, a uniform direction, its
    magnitude), each at every load fraction of the FE simulations.
    """
    rng = np.random.default_rng(seed)
    fractions = np.unique(np.round(ds.sample_fraction, 9))
    magnitude = float(np.max(np.linalg.norm(ds.forces[:, 0], axis=-1)
                             / np.maximum(ds.sample_fraction, 1e-12)))
    nodes = rng.choice(np.asarray(ds.loadable[0]), size=n_sims)
    d = rng.normal(size=(n_sims, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rep = fractions.size
    forces = np.repeat(magnitude * d, rep, axis=0) * np.tile(fractions, n_sims)[:, None]
    return (forces, np.repeat(nodes, rep), np.tile(fractions, n_sims),
            np.repeat(np.arange(n_sims), rep))


def with_cases(ds: Dataset, keep: np.ndarray, forces, nodes, fractions, sims,
               fields) -> Dataset:
    """A one-liver dataset of the samples ``keep`` of ``ds`` and new cases (one load each;
    ``fields`` (S, n_out, 3) mm) numbered after its simulations.
    """
    if ds.extra.shape[1]:
        raise ValueError(f"{ds.directory}: the patient's scene varies its material or shape "
                         "(extra inputs); a patient model is of one liver and one material")
    n_out = ds.out_nodes[0].size
    first = int(ds.sample_sim.max()) + 1
    rows = np.concatenate([np.arange(ds.sample_offset[s], ds.sample_offset[s] + n_out)
                           for s in keep]) if keep.size else np.zeros(0, int)
    targets = np.concatenate([np.asarray(ds.targets[rows], np.float32),
                              np.asarray(fields, np.float32).reshape(-1, 3)])
    n = keep.size + len(sims)
    return dataclasses.replace(
        ds, sample_geo=np.zeros(n, ds.sample_geo.dtype),
        sample_sim=np.concatenate([ds.sample_sim[keep], first + np.asarray(sims)]),
        sample_fraction=np.concatenate([ds.sample_fraction[keep], fractions]),
        forces=np.concatenate([ds.forces[keep], np.asarray(forces)[:, None]]),
        load_points=np.concatenate([ds.load_points[keep],
                                    ds.points[0][np.asarray(nodes)][:, None]]),
        load_nodes=np.concatenate([ds.load_nodes[keep], np.asarray(nodes)[:, None]]),
        extra=np.zeros((n, 0), ds.extra.dtype), targets=targets,
        sample_offset=np.arange(n + 1) * n_out)


def distilled(teacher: Teacher, ds: Dataset, sims, n_synthetic: int, cfg: dict,
              seed: int = 0, log_fn=print):
    """(model, dataset, linear part): the reduced basis trained on the FE simulations
    ``sims`` and ``n_synthetic`` drawn loads with the teacher's fields; with the small-strain
    Green's function (``fem_sim linear --green``), trained on what the fields hold beyond
    its exact small-strain part, which the exported model adds back at run time (the linear
    part: (nodes, unit responses), else None).
    """
    from surrogate.train import fit_design

    if teacher.linear is not None:   # the drawn cases of fem_sim linear, with their responses
        forces, nodes, fractions, sim, base = teacher.linear.drawn(n_synthetic)
        base = teacher.over_base(base, forces, ds.points[0][nodes])
        fields = teacher(forces, ds.points[0][nodes], base)
    else:
        forces, nodes, fractions, sim = drawn_loads(ds, n_synthetic, seed)
        fields = teacher(forces, ds.points[0][nodes])
    aug = with_cases(ds, sims_samples(ds, sims), forces, nodes, fractions, sim, fields)
    part = None if teacher.linear is None else teacher.linear.green
    if part is not None:
        exact = teacher.linear.green_part(aug.load_nodes[:, 0], aug.forces[:, 0])
        aug = dataclasses.replace(aug, targets=(np.asarray(aug.targets, np.float64)
                                                - exact.reshape(-1, 3)).astype(np.float32))
    model, _ = fit_design(aug, np.arange(aug.n_samples), cfg, seed, "patient ", log_fn)
    return model, aug, part


def student_config(**overrides) -> dict:
    """The distilled model's config: the reduced basis, one network, no cross-validation."""
    from surrogate.config import get_config

    return get_config("basis", **{**STUDENT, **overrides})
