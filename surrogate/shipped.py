"""The models of forces the project ships (``models/``), and the figures of their cards.

    python -m surrogate.shipped card MODEL TRUTH LIVER --out MODEL/card.json
    python -m surrogate.shipped grasp-card MODEL TRUTH.npz --out MODEL/card.json

A card's figures are measured on the FE truth of one validation liver no training saw
(``make truth``'s steps with a few simulations: the liver meshed as the population's livers,
the model's boundary condition, the scene's 0.4 N forces; a model over the small-strain base
also needs that truth's base, ``fem_sim linear``): per simulation, at its last load step, the
model's MEE and share of nodes under 3 mm, its base's MEE alone (a model over a base), and the
naive model's (the truth's own mean displacement). A model of grasps's card is measured on
``fem_sim.batch.grasp_truth``'s grasps of that liver: at every pull, the model's and its base's
MEE, share under 3 mm and force error. make test measures them again
(tests/surrogate/test_shipped_model.py) and holds them to the card's tolerance.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "models"
FORCES = SHIPPED / "scene4_forces"   # population_green: make liver AT=... with no MODEL
GRASPS = SHIPPED / "scene4_grasp"    # a model of grasps: make liver GRASP=... with no MODEL
BASIS = SHIPPED / "scene4_basis"     # population_basis: predict-liver with no RUN (no FE)
TOLERANCE = {"mee_relative": 0.02}
GRASP_TOLERANCE = {"mee_relative": 0.02, "force_error_points": 2.0}


def reference_figures(pred, truth: str | Path, liver: str | Path, mesh: str | Path) -> list:
    """Per simulation of the truth data directory ``truth`` (its liver file ``liver``, meshed
    as ``mesh``): ``sim``, ``force_n``, ``model_mee_mm``, ``model_lt3_pct``, ``base_mee_mm``
    (None for a model with no base) and ``naive_mee_mm`` at its last converged load step.
    """
    from data_spec.geometry import read_geometry
    from data_spec.shards import geometry_path, list_shards, read_shard
    from surrogate.evaluate import _base_of, _placed_fields, place
    from surrogate.linear_base import case_base
    from surrogate.metrics import displacement_metrics, mee

    truth = Path(truth)
    shards = [sh for sh in map(read_shard, list_shards(truth)) if sh.n_done]
    if not shards:
        raise ValueError(f"{truth}: no simulation with a converged load step")
    points = read_geometry(geometry_path(truth, shards[0].geometry_id)).points
    placement, _ = place(pred, liver, None, mesh=mesh)
    base = _base_of(pred, truth)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # every step of every simulation, placed once
        got, true, _ = _placed_fields(pred, placement, None, points, shards, base)
    naive = true.mean(axis=0)
    rows, end = [], 0
    for sh in shards:
        n = sh.output_nodes.size
        end += sh.n_done * n   # this simulation's last step: the n rows before ``end``
        last_got, last_true = got[end - n:end], true[end - n:end]
        m = displacement_metrics(last_got, last_true)
        row = {"sim": int(sh.sim_index), "steps": int(sh.n_done),
               "force_n": np.round(np.asarray(sh.forces, dtype=float), 6).tolist(),
               "model_mee_mm": round(m["mee"], 4), "model_lt3_pct": round(m["pct_ee_lt_3mm"], 2),
               "naive_mee_mm": round(mee(np.broadcast_to(naive, last_true.shape), last_true), 4),
               "base_mee_mm": None}
        if base is not None:
            fr = np.asarray(sh.load_fractions[:sh.n_done])
            u = case_base(base, pred.base.order, sh.sim_index, fr)[-1]
            row["base_mee_mm"] = round(mee(u.reshape(-1, 3), last_true), 4)
        rows.append(row)
    return rows


def truth_grasps(z) -> list[dict]:
    """The grasps of a ``fem_sim.batch.grasp_truth`` file ``z`` (its loaded .npz), as
    :func:`surrogate.over_green.grasps_on_mesh` takes them.
    """
    return [{"centre": z["centres"][k], "pull": z["pulls"][k], "fractions": z["fractions"],
             **{key: z[f"{key}_{k}"] for key in ("patch", "base", "truth", "base_force",
                                                 "fe_force")}}
            for k in range(sum(name.startswith("truth_") for name in z.files))]


def grasp_figures(pred, truth: str | Path) -> list:
    """Per grasp of the truth file ``truth`` (``fem_sim.batch.grasp_truth``'s .npz) and per
    stored pull: the FE force, the model's and the small-strain base's MEE, % of nodes under
    3 mm and force error (%).
    """
    from surrogate.grasp import force_error_pct
    from surrogate.metrics import displacement_metrics
    from surrogate.over_green import grasps_on_mesh

    z = np.load(truth)
    grasps = truth_grasps(z)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rows = grasps_on_mesh(pred, z["points"], z["triangles"], grasps, z["fixed"])
    out = []
    for g, got in zip(grasps, rows):
        steps = []
        for s, row in enumerate(got):
            base = displacement_metrics(np.asarray(g["base"][s], np.float64), g["truth"][s])
            steps.append({
                "pull_mm": round(float(g["fractions"][s] * np.linalg.norm(g["pull"])), 3),
                "fe_force_n": np.round(np.asarray(g["fe_force"][s], float), 4).tolist(),
                "model_mee_mm": round(row["mee"], 4), "base_mee_mm": round(base["mee"], 4),
                "model_lt3_pct": round(row["lt3"], 2),
                "base_lt3_pct": round(base["pct_ee_lt_3mm"], 2),
                "model_force_error_pct": round(row["force_error"], 2),
                "base_force_error_pct": round(float(force_error_pct(g["base_force"][s],
                                                                    g["fe_force"][s])), 2)})
        out.append({"status": "ok", "steps": steps})
    return out


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m surrogate.shipped", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    c = sub.add_parser("card", help="measure a shipped model's card figures")
    c.add_argument("model", help="the shipped model's folder (models/NAME)")
    c.add_argument("truth", help="the truth's folder: mesh.h5, scene.toml and data/")
    c.add_argument("liver", help="the liver file the truth was made from")
    c.add_argument("--out", help="write card.json here (default: print it)")
    g = sub.add_parser("grasp-card", help="measure a shipped model of grasps' card figures")
    g.add_argument("model", help="the shipped model's folder (models/NAME)")
    g.add_argument("truth", help="fem_sim.batch.grasp_truth's .npz of the card's liver")
    g.add_argument("--out", help="write card.json here (default: print it); the card's "
                   "other keys there (training, validation livers, the liver's file) are kept")
    return p


def _grasp_card(a) -> dict:
    """A model of grasps' card: the kept card's keys with the figures measured again."""
    from surrogate.predictor import load_predictor

    model = Path(a.model)
    pred = load_predictor(model / "model", load="grasp")
    kept = Path(a.out) if a.out else model / "card.json"
    card = json.loads(kept.read_text()) if kept.exists() else {}
    card.update({"model": model.name, "load": "grasp", "tolerance": GRASP_TOLERANCE})
    card.setdefault("reference_liver", {})["grasps"] = grasp_figures(pred, a.truth)
    return card


def _card(a) -> dict:
    """A model of forces' card: its figures on the truth's simulations."""
    from surrogate.predictor import load_predictor

    model, truth = Path(a.model), Path(a.truth)
    pred = load_predictor(model / "model")
    rows = reference_figures(pred, truth / "data", a.liver, truth / "mesh.h5")
    liver = Path(a.liver).resolve()
    return {"model": model.name, "load": "nodal", "tolerance": TOLERANCE,
            "reference_liver": {"file": str(liver.relative_to(ROOT.parent / "shared" / "data"
                                                              / "livers")),
                                "sims": rows}}


def main(argv=None) -> int:
    a = _parser().parse_args(argv)
    text = json.dumps(_grasp_card(a) if a.command == "grasp-card" else _card(a), indent=1)
    if a.out:
        Path(a.out).write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
