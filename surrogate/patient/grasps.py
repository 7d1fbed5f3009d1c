"""A patient's model of grasps (``make patient LOAD=grasp``): the population model of grasps
placed on the patient's liver over its own Green's function (what ``make liver GRASP=...``
answers: :class:`~surrogate.over_green.GraspOverGreen`), corrected with K FE grasps of the
patient, solved on its own mesh with the model's boundary condition.

Two corrections of one tool's grasp, each the residual of the patient's FE against the model
regressed on the grasp by kernel ridge regression
(:func:`~surrogate.patient.correction.fit_correction`: a decay in the distance between the
grasps' centres times a polynomial of their pulls, plus the product of the model's answers;
its setting, and whether to keep it at all, chosen by nested cross-validation over whole
simulations):

- the tool's force, its residual against the model's force (the population's stiffening of
  the small-strain force is one law over every liver and direction, while the FE's ratio to
  the small-strain force varies several-fold between grasps of one liver, with the pull's
  direction: docs/surgical_loads.md, docs/patient_grasps.md);
- the field, its residual against the model's field.

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

from surrogate.grasp import force_error_pct
from surrogate.patient.correction import Correction, fit_correction

FILE = "grasp_patient.npz"
REACH = 20.0   # mm: a grasp this near one the corrections were fitted on is corrected


@dataclasses.dataclass
class PatientGrasp:
    """What a patient's K grasps add to the placed population model of grasps: corrections
    of one tool's force and field (None: none kept). A grasp whose centre lies beyond REACH
    of every grasp they were fitted on (the patient's grasps were drawn around a site), or
    several tools, get none: the population model's answer there. ``model``: the digest of
    the population model they correct (:func:`surrogate.model_files.model_digest`).
    """

    force: Correction | None
    field: Correction | None
    model: str = ""

    def check_model(self, directory) -> None:
        """ValueError when the corrections were fitted on another model than ``directory``'s
        (a residual of one model's answers added to another's is a wrong answer).
        """
        from surrogate.model_files import model_digest

        if self.model != (now := model_digest(directory)):
            raise ValueError(f"the patient's corrections were fitted on another population "
                             f"model (digest {self.model or 'not recorded'}) than {directory} "
                             f"({now}): run make patient LOAD=grasp again with this model")

    def distance(self, centre) -> float:
        """The distance (mm) from ``centre`` (3,) to the nearest grasp the corrections were
        fitted on (inf with none kept).
        """
        seen = [c.cases[0] for c in (self.force, self.field) if c is not None]
        if not seen:
            return float("inf")
        return float(np.linalg.norm(np.concatenate(seen) - np.reshape(centre, (1, 3)),
                                    axis=1).min())

    def beyond(self, centres) -> str:
        """Why a grasp of tools at ``centres`` (T, 3) mm gets no correction, or ""."""
        centres = np.reshape(centres, (-1, 3))
        if self.force is None and self.field is None:
            return ""
        if len(centres) != 1:
            return f"{len(centres)} tools: the patient's corrections are of one tool's grasp"
        far = self.distance(centres[0])
        if far > REACH:
            return (f"the grasp at {np.round(centres[0], 1).tolist()} mm lies {far:.0f} mm from "
                    f"the patient's grasps (beyond {REACH:g} mm): the population model's "
                    "answer there, with no patient correction")
        return ""

    def _added(self, c: Correction | None, centre, d, answer, near: bool | None) -> np.ndarray:
        answer = np.asarray(answer, np.float64)
        near = self.beyond(centre) == "" if near is None else near
        if c is None or not near or np.asarray(d).shape != (1, 3):
            return np.zeros_like(answer)
        return c(np.reshape(centre, (1, 3)), np.reshape(d, (1, 3)),
                 answer.reshape(1, -1))[0].reshape(answer.shape)

    def field_added(self, centre, d, u, near: bool | None = None) -> np.ndarray:
        """(n_out, 3) mm to add to the model's field ``u`` (n_out, 3) of one tool at the point
        ``centre`` (3,) mm pulled by ``d`` (1, 3) mm; ``near``: :meth:`beyond` said "" (the
        caller checked once per grasp; None: checked here).
        """
        return self._added(self.field, centre, d, u, near)

    def force_added(self, centre, d, f, near: bool | None = None) -> np.ndarray:
        """(1, 3) N to add to the model's force ``f`` (1, 3) of the same tool."""
        return self._added(self.force, centre, d, f, near)

    def save(self, run) -> Path:
        path = Path(run) / FILE
        arrays = {}
        for name, c in (("force", self.force), ("field", self.field)):
            if c is not None:
                arrays.update({f"{name}_case_{i}": a for i, a in enumerate(c.cases)},
                              **{f"{name}_weights": c.weights,
                                 f"{name}_scales": np.asarray(c.scales),
                                 f"{name}_cv": np.float64(c.cv_mee),
                                 f"{name}_setting": np.asarray(json.dumps(list(c.setting)))})
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, model=np.asarray(self.model), **arrays)
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
            def read(name):
                if f"{name}_weights" not in f:
                    return None
                return Correction(tuple(f[f"{name}_case_{i}"] for i in range(4)),
                                  f[f"{name}_weights"],
                                  tuple(json.loads(str(f[f"{name}_setting"]))),
                                  tuple(map(float, f[f"{name}_scales"])),
                                  cv_mee=float(f[f"{name}_cv"]))
            return cls(read("force"), read("field"), str(f["model"]) if "model" in f else "")


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


def fit_patient_grasp(c: GraspCases) -> tuple[PatientGrasp, dict]:
    """The patient's corrections fitted on its grasp cases ``c`` (:func:`grasp_cases`)."""
    n = len(c.sims)
    force = fit_correction(c.centres, c.pulls, c.model_force, c.fe_force - c.model_force,
                           c.sims)
    field = fit_correction(c.centres, c.pulls, c.model.reshape(n, -1),
                           (c.truth - c.model).reshape(n, -1), c.sims)
    keys = ("length_mm", "beta", "mix", "decay", "gamma", "ridge")
    return PatientGrasp(force, field), {
        name: None if k is None else {**dict(zip(keys, k.setting)), f"cv_{unit}": k.cv_mee}
        for name, k, unit in (("force", force, "error_n"), ("field", field, "mee_mm"))}


def answered(pg: PatientGrasp, c: GraspCases) -> tuple[np.ndarray, np.ndarray]:
    """(fields (n, n_out, 3) mm, forces (n, 3) N) of the patient's model for the cases ``c``."""
    u = np.array([m + pg.field_added(x, d[None], m)
                  for x, d, m in zip(c.centres, c.pulls, c.model)])
    f = np.array([m + pg.force_added(x, d[None], m[None])[0]
                  for x, d, m in zip(c.centres, c.pulls, c.model_force)])
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
    from surrogate.model_files import model_digest
    from surrogate.over_green import OverGreen

    t = time.perf_counter()
    placement, found = place(pred, liver, frame, saved)
    placed = time.perf_counter()
    every = grasp_cases(OverGreen(pred, data, placement), ds, np.unique(ds.sample_sim))
    answered_at = time.perf_counter()
    pg, fitted = fit_patient_grasp(every.take(np.isin(every.sims, used)))
    pg.model = model_digest(model_dir)
    pg.save(run)
    said = {True: "kept", False: "not kept (no better held out)"}
    log_fn(f"adapt: {len(used)} simulations: the force's correction {said[pg.force is not None]}"
           f", the field's {said[pg.field is not None]}")
    rest = ~np.isin(every.sims, used)
    return {"population_model": str(Path(model_dir).resolve()), "load": "grasp",
            "liver": str(Path(liver).resolve()), "data": str(Path(data).resolve()),
            "placement_residual_mm": placement.residual, "warnings": list(found),
            "fe_simulations": np.asarray(used).tolist(), **fitted,
            "held_out_simulations": np.unique(every.sims[rest]).astype(int).tolist(),
            "held_out": held_out(pg, every.take(rest)) if rest.any() else None,
            "seconds": {"place": placed - t, "model_answers": answered_at - placed,
                        "correction": time.perf_counter() - answered_at,
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
        rows.append({"k": int(k), "force": info["force"] is not None,
                     "field": info["field"] is not None, **held_out(pg, test, large_mm)})
    return rows


def timed(over, at, d, calls: int = 200) -> dict:
    """Median seconds of one grasp's frame (field and force) and of its force alone (a haptic
    loop's call) at the point ``at`` (3,) mm pulled by ``d`` (3,) mm, over ``calls`` calls
    after a warm-up, with ``over``'s model (and its patient's corrections, if any).
    """
    grasp, d = over.grasp(np.reshape(at, (1, 3))), np.reshape(d, (1, 3))
    out = {}
    for key, call in (("frame_s", grasp), ("force_s", grasp.force)):
        for _ in range(10):
            call(d)
        t = []
        for _ in range(calls):
            t0 = time.perf_counter()
            call(d)
            t.append(time.perf_counter() - t0)
        out[key] = float(np.median(t))
    return out
