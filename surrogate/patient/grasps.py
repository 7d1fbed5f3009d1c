"""A patient's model of grasps (``make patient LOAD=grasp``): the population model of grasps
placed on the patient's liver over its own Green's function (what ``make liver GRASP=...``
answers: :class:`~surrogate.over_green.GraspOverGreen`), corrected with K FE grasps of the
patient, solved on its own mesh with the model's boundary condition.

Two corrections, each kept only when it beats the population model on the patient's
simulations held out in turn:

- the tool's force: the stiffening of the small-strain force refitted on the patient's
  grasps (:class:`~surrogate.grasp.GraspForce`: the population's law is one fit over every
  liver, and a liver's own ratio of FE to small-strain force differs by a factor of up to
  two; docs/surgical_loads.md); chosen by leave-one-simulation-out error of the log-ratio;
- the field: the residual of the FE fields against the model regressed on the grasp by
  kernel ridge regression (:func:`~surrogate.patient.correction.fit_correction`: a decay in
  the distance between the grasps' centres times a polynomial of their pulls, plus the
  model fields' product; its setting and whether to keep it chosen by nested
  cross-validation over whole simulations), for one tool at a time.

    python -m surrogate adapt MODEL DATA --liver FILE --run OUT [--sims K] [--placement P]

writes ``OUT/grasp_patient.npz`` (what :meth:`PatientGrasp.load` reads) and
``OUT/adaptation.json`` (what was fitted, its cross-validated errors and, with simulations
beyond the K, the errors on those held out). ``predict-liver MODEL LIVER --base DATA --grasp
... --patient OUT`` and the manipulator's ``--patient OUT`` answer with it. numpy only.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from surrogate.grasp import GraspForce, force_error_pct
from surrogate.patient.correction import Correction, fit_correction

FILE = "grasp_patient.npz"


@dataclasses.dataclass
class PatientGrasp:
    """What a patient's K grasps add to the placed population model of grasps."""

    force: GraspForce | None          # the patient's force law (None: the population's)
    correction: Correction | None     # the field's residual on one tool's grasp (None: none)

    def field(self, centre, d, u) -> np.ndarray:
        """(n_out, 3) mm to add to the model's field ``u`` (n_out, 3) of one tool at the
        point ``centre`` (3,) mm pulled by ``d`` (1, 3) mm; zero for several tools.
        """
        u = np.asarray(u, np.float64)
        if self.correction is None or np.asarray(d).shape != (1, 3):
            return np.zeros_like(u)
        return self.correction(np.reshape(centre, (1, 3)), np.reshape(d, (1, 3)),
                               u.reshape(1, -1))[0].reshape(u.shape)

    def save(self, run) -> Path:
        c, path = self.correction, Path(run) / FILE
        arrays = {} if c is None else {
            **{f"case_{i}": a for i, a in enumerate(c.cases)}, "weights": c.weights,
            "scales": np.asarray(c.scales), "cv_mee": np.float64(c.cv_mee),
            "setting": np.asarray(json.dumps(list(c.setting)))}
        if self.force is not None:
            arrays["force_abc"] = np.array([self.force.a, self.force.b, self.force.c])
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, **arrays)
        return path

    @classmethod
    def load(cls, run) -> PatientGrasp:
        """From ``run`` (``surrogate adapt``'s directory) or its file; ValueError naming what
        to run when it is missing.
        """
        path = Path(run)
        path = path if path.suffix == ".npz" else path / FILE
        if not path.is_file():
            raise ValueError(f"{path}: missing: not a patient's model of grasps (make patient "
                             "LOAD=grasp writes it)")
        with np.load(path) as f:
            force = GraspForce(*map(float, f["force_abc"])) if "force_abc" in f else None
            correction = None
            if "weights" in f:
                correction = Correction(tuple(f[f"case_{i}"] for i in range(4)), f["weights"],
                                        tuple(json.loads(str(f["setting"]))),
                                        tuple(map(float, f["scales"])),
                                        cv_mee=float(f["cv_mee"]))
        return cls(force, correction)


@dataclasses.dataclass
class GraspCases:
    """One-tool grasp samples of a patient's dataset with the placed model's answer."""

    sims: np.ndarray        # (n,) the simulation of each sample
    centres: np.ndarray     # (n, 3) mm: the tool's centre
    pulls: np.ndarray       # (n, 3) mm: its displacement at the sample's step
    model: np.ndarray       # (n, n_out, 3) mm: the population model's field
    truth: np.ndarray       # (n, n_out, 3) mm: the FE field
    base_force: np.ndarray  # (n, 3) N: the small-strain force
    model_force: np.ndarray  # (n, 3) N: the population model's
    fe_force: np.ndarray    # (n, 3) N: the FE reaction

    def take(self, keep) -> GraspCases:
        return GraspCases(*(getattr(self, f.name)[keep] for f in dataclasses.fields(self)))


def grasp_cases(over, ds, sims) -> GraspCases:
    """The converged steps of the simulations ``sims`` of the patient's grasp dataset ``ds``
    (one tool each) answered by ``over`` (an :class:`~surrogate.over_green.OverGreen` of the
    population model of grasps on the same mesh).
    """
    if ds.forces.shape[1] != 1:
        raise ValueError(f"{ds.directory}: {ds.forces.shape[1]} tools a simulation; a patient's "
                         "model of grasps is fitted on one tool's grasps")
    if not np.array_equal(np.asarray(ds.out_nodes[0]), over.output_nodes):
        raise ValueError(f"{ds.directory}: its output nodes are not those of its linear.h5")
    rows: dict = {k: [] for k in ("sims", "centres", "pulls", "model", "truth", "base_force",
                                  "model_force", "fe_force")}
    for sim in sims:
        samples = np.flatnonzero(ds.sample_sim == sim)
        grasp = over.grasp(ds.load_points[samples[0]])
        for s in samples:
            d = np.asarray(ds.forces[s], np.float64)
            u, f = grasp(d)
            for k, v in (("sims", sim), ("centres", ds.load_points[s, 0]), ("pulls", d[0]),
                         ("model", u), ("truth", ds.targets[ds.sample_offset[s]:
                                                            ds.sample_offset[s + 1]]),
                         ("base_force", grasp.base.force(d)[0]), ("model_force", f[0]),
                         ("fe_force", ds.reactions[s, 0])):
                rows[k].append(v)
    return GraspCases(**{k: np.asarray(v, np.float64) for k, v in rows.items()})


def _log_ratio_error(law: GraspForce | None, c: GraspCases) -> float:
    """Mean squared log of the FE to the predicted force's magnitude over the cases ``c``
    (``law`` None: the population model's force).
    """
    f = c.model_force if law is None else law(c.pulls, c.base_force)
    return float(np.mean(np.log(np.linalg.norm(c.fe_force, axis=1)
                                / np.linalg.norm(f, axis=1)) ** 2))


def fit_force(c: GraspCases) -> tuple[GraspForce | None, dict]:
    """The patient's force law, exp(a p + b p^2) or with c |F_lin| (:class:`GraspForce`),
    whichever has the least error of the log-ratio on each of its simulations held out in
    turn (at least two), when that beats the population's; with the errors of each.
    """
    sims = np.unique(c.sims)
    if sims.size < 2:
        return None, {"kept": None, "why": "fewer than two simulations"}
    cv = dict.fromkeys(("population", "patient", "patient_with_force"), 0.0)
    for s in sims:
        held, train = c.take(c.sims == s), c.take(c.sims != s)
        cv["population"] += _log_ratio_error(None, held) / sims.size
        for key, with_force in (("patient", False), ("patient_with_force", True)):
            law = GraspForce.fit(train.pulls, train.base_force, train.fe_force, with_force)
            cv[key] += _log_ratio_error(law, held) / sims.size
    best = min(cv, key=cv.get)
    law = None if best == "population" else GraspForce.fit(
        c.pulls, c.base_force, c.fe_force, best == "patient_with_force")
    return law, {"kept": best, **({} if law is None else dataclasses.asdict(law)),
                 "cv_rms_log_ratio": {k: float(np.sqrt(v)) for k, v in cv.items()}}


def fit_patient_grasp(c: GraspCases) -> tuple[PatientGrasp, dict]:
    """The patient's corrections fitted on its grasp cases ``c`` (:func:`grasp_cases`)."""
    force, finfo = fit_force(c)
    n = len(c.sims)
    r = (c.truth - c.model).reshape(n, -1)
    corr = fit_correction(c.centres, c.pulls, c.model.reshape(n, -1), r, c.sims)
    return PatientGrasp(force, corr), {
        "force": finfo, "field": None if corr is None else {
            **dict(zip(("length_mm", "beta", "mix", "decay", "gamma", "ridge"), corr.setting)),
            "cv_mee_mm": corr.cv_mee}}


def answered(pg: PatientGrasp, c: GraspCases) -> tuple[np.ndarray, np.ndarray]:
    """(fields (n, n_out, 3) mm, forces (n, 3) N) of the patient's model for the cases ``c``."""
    u = np.array([m + pg.field(x, d[None], m) for x, d, m in zip(c.centres, c.pulls, c.model)])
    f = c.model_force if pg.force is None else pg.force(c.pulls, c.base_force)
    return u, f


def held_out(pg: PatientGrasp, c: GraspCases, large_mm: float = 30.0) -> dict:
    """The population model's and the patient's MEE (mm) and force error (%) on the cases
    ``c`` (simulations the fit never saw): medians over every step and over pulls beyond
    ``large_mm``.
    """
    u, f = answered(pg, c)
    big = np.linalg.norm(c.pulls, axis=1) > large_mm
    out: dict = {"simulations": int(np.unique(c.sims).size), "large_mm": large_mm}
    for name, uu, ff in (("population", c.model, c.model_force), ("patient", u, f)):
        mee = np.linalg.norm(uu - c.truth, axis=2).mean(axis=1)
        fe = force_error_pct(ff, c.fe_force)
        out[name] = {"mee_mm": float(np.median(mee)), "force_error_pct": float(np.median(fe)),
                     "large_mee_mm": float(np.median(mee[big])) if big.any() else None,
                     "large_force_error_pct": float(np.median(fe[big])) if big.any() else None}
    return out


def adapt_grasps(pred, model_dir, ds, data, liver, run, used, *, frame: str | None = None,
                 saved=None, log_fn=print) -> dict:
    """``surrogate adapt`` for a model of grasps ``pred`` (loaded from ``model_dir``) and the
    patient's grasp dataset ``ds`` (read from ``data``, with its ``fem_sim linear --green``
    file): the corrections fitted on its simulations ``used``, the others measured; writes
    ``run/grasp_patient.npz`` and returns what ``run/adaptation.json`` holds.
    """
    from surrogate.evaluate import place
    from surrogate.over_green import OverGreen

    t = time.perf_counter()
    placement, found = place(pred, liver, frame, saved)
    over = OverGreen(pred, data, placement)
    every = grasp_cases(over, ds, np.unique(ds.sample_sim))
    placed = time.perf_counter()
    pg, fitted = fit_patient_grasp(every.take(np.isin(every.sims, used)))
    pg.save(run)
    law = "the patient's" if pg.force else "the population's"
    log_fn(f"adapt: {len(used)} simulations: {law} force law; the field's correction "
           f"{'kept' if pg.correction else 'not kept (no better held out)'}")
    rest = ~np.isin(every.sims, used)
    return {"population_model": str(Path(model_dir).resolve()), "load": "grasp",
            "liver": str(Path(liver).resolve()), "data": str(Path(data).resolve()),
            "placement_residual_mm": placement.residual, "warnings": list(found),
            "fe_simulations": np.asarray(used).tolist(), **fitted,
            "held_out_simulations": np.unique(every.sims[rest]).astype(int).tolist(),
            "held_out": held_out(pg, every.take(rest)) if rest.any() else None,
            "seconds": {"place": placed - t, "correction": time.perf_counter() - placed,
                        "total": time.perf_counter() - t}}


def grasp_site(pred, liver, clear: float = 50.0) -> list[float]:
    """A vertex of the liver file at least ``clear`` mm from where ``pred``'s placement puts
    the template's fixed region (the liver file's frame), drawn from the file's name: a site
    for ``make patient LOAD=grasp SITE=...`` whose 20 mm reach keeps the scene's 30 mm from it.
    """
    import zlib

    from data_spec.eligible_loads import min_distance
    from surrogate.evaluate import place
    from surrogate.predict_liver import read_liver_surface

    pl = place(pred, liver, None)[0]
    vertices = read_liver_surface(liver)[0]
    far = vertices[min_distance(vertices, pl.to_liver(pl.points[pred.shape_model.fixed_nodes]))
                   >= clear]
    if not far.size:
        raise ValueError(f"{liver}: no surface vertex {clear:g} mm from the fixed region")
    rng = np.random.default_rng(zlib.crc32(Path(liver).stem.encode()))
    return [round(float(v), 2) for v in far[rng.integers(far.shape[0])]]


def against_k(c: GraspCases, ks, held: int, large_mm: float = 35.0) -> list[dict]:
    """Per K of ``ks``: the corrections fitted on the first K simulations of ``c`` (the last
    ``held`` left out), what was kept, and :func:`held_out` on those last ``held``.
    """
    sims = np.unique(c.sims)
    test, rows = c.take(np.isin(c.sims, sims[-held:])), []
    for k in ks:
        pg, info = fit_patient_grasp(c.take(np.isin(c.sims, sims[:-held][:k])))
        rows.append({"k": int(k), "force_law": info["force"]["kept"],
                     "field": info["field"] is not None, **held_out(pg, test, large_mm)})
    return rows
