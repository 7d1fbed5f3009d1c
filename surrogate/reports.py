"""The records the studies write and the report rows built from them, once: a design trained
and evaluated (:class:`DesignRecord`), its label, and the cells every report shows of it.
``bench/table4.py`` and ``bench/scene4_real.py`` read and write these; neither formats a
design's row on its own, nor asks a base's order (:mod:`surrogate.small_strain` does).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from surrogate.small_strain import SmallStrainBase, base_of


def design_label(config: str, variant: dict | None = None) -> str:
    """The design's name, its config and the overrides that make it a variant of it."""
    from surrogate.config import get_config
    from surrogate.designs import DESIGNS

    kind = DESIGNS[get_config(config)["design"]].label
    knobs = "".join(f", {key} = {json.dumps(v)}" for key, v in (variant or {}).items())
    return f"{kind} (`{config}`{knobs})"


@dataclasses.dataclass
class DesignRecord:
    """One design trained on a dataset and evaluated on held-out simulations: its config,
    the trainer's metrics (``train_and_evaluate``'s), and what the study added (latency at
    its own nodes and at 15.4k, its small-strain base alone, the run it was kept from).
    """

    config: str
    metrics: dict
    variant: dict | None = None
    nodes: int | None = None
    ms_own: float | None = None
    ms_big: float | None = None
    base_alone: dict | None = None
    kept_from: str | None = None
    extra: dict = dataclasses.field(default_factory=dict)

    @classmethod
    def from_json(cls, d: dict) -> DesignRecord:
        names = {f.name for f in dataclasses.fields(cls)} - {"extra"}
        return cls(**{k: v for k, v in d.items() if k in names},
                   extra={k: v for k, v in d.items() if k not in names})

    def to_json(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
             if f.name != "extra" and getattr(self, f.name) is not None}
        return {**d, **self.extra}

    @property
    def base(self) -> SmallStrainBase | None:
        """The small-strain base the design learns the rest of (None: a whole-field design)."""
        return None if self.base_alone is None else base_of(self.base_alone["order"])

    @property
    def label(self) -> str:
        return design_label(self.config, self.variant)

    def use_cell(self, exported: str = "{own:.2f} / {big:.2f}") -> str:
        """The latency cell: the exported model's ms, else how a whole field is had."""
        if self.ms_big is not None:
            return exported.format(own=self.ms_own, big=self.ms_big)
        return "not exported" if self.base is None else self.base.use

    def per_liver_skill(self) -> str:
        """Mean / median over the held-out livers of each liver's skill."""
        pl = self.metrics["per_liver_mee"]
        return f"{pl['skill_mean']:.3f} / {pl['skill_median']:.3f}"


def surgical_per_liver(records: list[dict], kind: str, key: str, at) -> dict:
    """bench/surgical_loads.py's records (a liver each: its ``grasps`` and ``forces``, each a
    case with its status and steps) at the step whose ``key`` (pull mm, force N) is ``at``:
    {liver: {model: {metric: the mean over its converged cases of ``kind``}}}, the models
    those every step has (model, base, naive); for grasps also the force errors (base's
    ``force_error``, the model's ``model_force_error``) and the FE force's size.
    """
    out = {}
    for r in records:
        steps = [s for c in r[kind] if c["status"] == "ok" for s in c["steps"] if s[key] == at]
        if not steps:
            continue
        row = {m: {k: float(np.mean([s[m][k] for s in steps])) for k in steps[0][m]}
               for m in ("model", "base", "naive") if all(m in s for s in steps)}
        if kind == "grasps":
            for k in ("force_error", "model_force_error")[:1 + ("model" in row)]:
                row[k] = float(np.mean([s[k] for s in steps]))
            row["fe_force"] = float(np.mean([np.linalg.norm(s["fe_force"]) for s in steps]))
        out[r["liver"]] = row
    return out


def per_liver_at(values: dict, pull, liver) -> dict:
    """{pull (mm, as text): {name: [each liver's mean of ``values[name]`` at that pull]}},
    the arrays of ``values`` aligned with the pulls ``pull`` (to 0.1 mm) and ``liver``.
    """
    pull, liver = np.round(np.asarray(pull, np.float64), 1), np.asarray(liver)
    return {f"{p:g}": {m: [float(np.mean(np.asarray(v)[(pull == p) & (liver == g)]))
                           for g in np.unique(liver[pull == p])] for m, v in values.items()}
            for p in np.unique(pull)}


def grasp_force_section(data, folds: int, commit: str) -> str:
    """The tool's force on the held-out livers of every liver fold of the grasp dataset
    ``data`` (no network), the laws side by side (:func:`surrogate.grasp.heldout_forces`):
    a report's section, per pull the median / worst liver.
    """
    from surrogate.config import get_config
    from surrogate.data import kfold_groups, load_dataset
    from surrogate.grasp import heldout_forces

    cfg, ds = get_config("population_green", folds=folds), load_dataset(data)
    got = heldout_forces(ds, kfold_groups(ds, folds, cfg["seed"]), cfg)
    lines = [f"The tool's force on the held-out livers of all {folds} folds by liver "
             f"({np.unique(got['liver']).size} livers, {got['pull'].size} samples; commit "
             f"{commit}; no network: `surrogate.grasp.heldout_forces`), error % per liver (the "
             "mean over its grasps at that pull), median / worst: the small-strain base; the "
             "law of the pull alone, exp(a p + b p^2); the shipped law "
             "(`surrogate.grasp.GraspForce`: the pull, the grasp's small-strain stiffness along "
             "it, its distance to the fixed region and the cosine between the pull and the "
             "small-strain force); the floor of any law that scales the base's force (the FE "
             "force's part across it).", "", "| pull mm | base | pull alone | law | floor |",
             "|---" * 5 + "|"]
    laws = {c: got[c] for c in ("base", "law_pull", "law", "floor")}
    for p, per in per_liver_at(laws, got["pull"], got["liver"]).items():
        lines.append(f"| {p} | " + " | ".join(f"{np.median(v):.1f} / {np.max(v):.1f}"
                                              for v in per.values()) + " |")
    return "\n".join(lines)


HELD_BINS = (0.0, 0.6, 1.5, 3.0, 5.0, np.inf)   # N: the held forces' bins


def held_force_rows(over, c) -> list[dict]:
    """The grasp cases ``c`` (:func:`surrogate.patient.grasps.grasp_cases`, one tool each,
    answered by ``over``, their liver's :class:`~surrogate.over_green.OverGreen`) answered as
    forces held by the tool: each FE reaction given to the model's
    :meth:`~surrogate.over_green.GraspOverGreen.pull_for`. Per bin of :data:`HELD_BINS` with
    samples, the means over them of the force (N); the pull's error (mm) of the model and of
    the small-strain inverse K^-1 F; the MEE (mm) of their fields against the FE, and of the
    model's at the FE's own pull (the cases' answer).
    """
    from surrogate.metrics import mee

    out = {k: [] for k in ("force", "pull_model", "pull_base", "model", "base", "at_pull")}
    for sim in np.unique(c.sims):
        rows = np.flatnonzero(c.sims == sim)
        grasp = over.grasp(c.centres[rows[0]][None])
        for i in rows:
            f, d, truth = c.fe_force[i][None], c.pulls[i][None], c.truth[i]
            dm, dl = grasp.pull_for(f), np.linalg.solve(grasp.stiffness, f[0])[None]
            for k, v in (("force", np.linalg.norm(f)), ("pull_model", np.linalg.norm(dm - d)),
                         ("pull_base", np.linalg.norm(dl - d)),
                         ("model", mee(grasp(dm)[0], truth)),
                         ("base", mee(grasp.base(dl)[0], truth)),
                         ("at_pull", mee(c.model[i], truth))):
                out[k].append(float(v))
    v = {k: np.asarray(x) for k, x in out.items()}
    return [{"lo": lo, "hi": hi, "n": int(at.sum()), **{k: float(x[at].mean())
                                                       for k, x in v.items()}}
            for lo, hi in zip(HELD_BINS[:-1], HELD_BINS[1:])
            if (at := (v["force"] > lo) & (v["force"] <= hi)).any()]


def held_force_table(livers: list[dict]) -> list[dict]:
    """Per bin of :data:`HELD_BINS`, over the livers' :func:`held_force_rows` (``held``):
    the livers and samples, and per column (median, worst) of the livers' means.
    """
    rows = []
    for lo, hi in zip(HELD_BINS[:-1], HELD_BINS[1:]):
        at = [b for liver in livers for b in liver["held"] if b["lo"] == lo]
        if at:
            rows.append({"lo": lo, "hi": hi, "livers": len(at), "n": sum(b["n"] for b in at),
                         **{k: (float(np.median([b[k] for b in at])),
                                float(np.max([b[k] for b in at])))
                            for k in ("force", "pull_model", "pull_base", "model", "base",
                                      "at_pull")}})
    return rows


def surgical_curve(records: list[dict], kind: str, key: str, values) -> list[dict]:
    """Per value of ``key`` in ``values``: the median and worst liver of each model's
    figures (:func:`surgical_per_liver`) over the livers that reached it, and for grasps each
    model's force error.
    """
    rows = []
    for v in values:
        livers = surgical_per_liver(records, kind, key, v)
        if not livers:
            continue
        ls = list(livers.values())

        def of(f, m, k, ls=ls):
            return float(f([x[m][k] if m else x[k] for x in ls]))

        row = {key: v, "livers": len(ls), "mean_u": of(np.median, "base", "mean_u")}
        for m in (m for m in ("model", "base", "naive") if all(m in x for x in ls)):
            row[m] = {"mee_median": of(np.median, m, "mee"), "mee_worst": of(np.max, m, "mee"),
                      "p95_median": of(np.median, m, "p95"), "lt3_median":
                      of(np.median, m, "lt3"), "lt3_worst": of(np.min, m, "lt3")}
            if kind == "grasps" and m != "naive":   # the tool's force, % off
                e = "model_force_error" if m == "model" else "force_error"
                row[m].update(force_median=of(np.median, None, e), force_worst=of(np.max, None, e))
        if kind == "grasps":
            row.update(force_error_median=row["base"]["force_median"], force_error_worst=row[
                "base"]["force_worst"], fe_force=of(np.median, None, "fe_force"))
        rows.append(row)
    return rows


def surgical_worst_picture(records: list[dict], results: Path, png: Path) -> str | None:
    """``png`` (docs/surgical_loads_worst.png): bench/surgical_loads.py's worst liver's worst
    40 mm grasp (its fields in ``results``), FE beside the model of grasps (when measured), the
    small-strain base and the error of the first; what it shows, or None.
    """
    from liverviz.pictures import Panel, Surface, render_panels

    g40 = surgical_per_liver(records, "grasps", "pull", 40.0)
    m = "model" if g40 and all("model" in v for v in g40.values()) else "base"
    name = max((n for n in g40 if (results / f"{n}.npz").exists()),
               key=lambda n: g40[n][m]["mee"], default=None)
    if name is None:
        return None
    z = dict(np.load(results / f"{name}.npz"))   # the mesh, and the base's worst grasp
    shown = {"small-strain base": z["base"]}
    if m == "model":   # the model's worst grasp of the liver, every field from its files
        cases = next(r for r in records if r["liver"] == name)["grasps"]
        k = max((k for k, c in enumerate(cases) if c["status"] == "ok"),
                key=lambda k: cases[k]["steps"][-1]["model"]["mee"])
        f, fm = (np.load(results / "fields" / f"{name}{x}.npz") for x in ("", "_model"))
        z.update(truth=f[f"truth_{k}"][-1], patch=f[f"patch_{k}"])
        shown = {"model of grasps": fm[f"model_{k}"], "small-strain base": f[f"base_{k}"][-1]}
    s, centre = Surface.from_mesh(z["points"], z["triangles"], z["fixed"]), z["patch"][:1]
    err = np.linalg.norm(z["truth"] - next(iter(shown.values())), axis=1)[s.nodes]
    panels = [Panel(s, u[s.nodes], label=label, load_nodes=centre)
              for label, u in {"FE (Ogden)": z["truth"], **shown}.items()]
    panels.append(Panel(s, z["truth"][s.nodes], scalars=err, title=f"{m} error (mm)",
                        label=f"|FE - {m}|", load_nodes=centre))
    render_panels(panels, png, title=f"{name}: a 10 mm grasp pulled 40 mm")
    return f"{name} ({m} MEE {g40[name][m]['mee']:.2f} mm at 40 mm)"


def xyz(m: dict, key: str, fmt: str = "{:.3f}") -> str:
    """``key``'s x / y / z values of a metrics dict (``mae`` or ``corr``)."""
    return " / ".join(fmt.format(m[f"{key}_{c}"]) for c in "xyz")


# What every report template may call (liverviz.report.render's context):
# ``render(template, **REPORT_NAMES, ...)``.
REPORT_NAMES = {
    "label": design_label, "xyz": xyz, "nan": math.nan, "record": DesignRecord.from_json,
    "mean": lambda xs: float(np.mean(list(xs))), "median": lambda xs: float(np.median(list(xs)))}
