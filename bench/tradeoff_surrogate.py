"""Surrogate price list and the end-to-end error budget, measured on this software.

On scene 1 (one liver, one random 0.4 N nodal force, 10 load steps) the study trains the node-wise
MLP with one knob changed at a time and measures it on the same held-out simulations:

- learning curve: 25, 50, 100, 200, 400 training simulations (the paper's scene-1 network);
- network size: the paper's architectures (scene 1; scenes 2-3; scene 4) and smaller ones;
- sampled node fraction per epoch;
- inference precision: float32, bfloat16, float16 (the same trained weights, cast);
- all nodes against the surface nodes only (a model trained on all nodes, evaluated on the
  surface; and a model trained on surface nodes only).

Each row gives MEE, the 95th percentile of the Euclidean error, % of nodes under 1 mm, training
seconds and the inference latency of the whole liver (median of repeated jitted calls).

The error budget (``docs/error_budget.png``): for each mesh (P1 and P2 at several sizes) a dataset
of the same scene on that mesh, a surrogate trained on it, and, for a few held-out load cases,
the FE error of that mesh against the fine reference of ``bench/budget_fem.py`` (P2 at 6 mm),
the surrogate's error against its own FE data, and the surrogate's error against the reference:
the error a user of the trained surrogate actually gets. With the cost of each: simulation
CPU-hours for the dataset plus training hours.

    make tradeoff-surrogate       # budget_fem.py (solver env), then this script (trainer env)
    .venv-train/bin/python bench/tradeoff_surrogate.py --report   # report only

Resumable: datasets are generated with ``fem_sim generate`` (which skips finished shards) into
``bench/results/tradeoff_surrogate/data``; every training appends one line to
``runs.jsonl`` and finished runs are skipped.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from fem_sim.batch.chunked import mpirun_env
from fem_sim.batch.knob_run import (
    BUDGET_CASES,
    BUDGET_MESHES,
    BUDGET_REFERENCE,
    BUDGET_RESULTS,
    BUDGET_RUNS,
    budget_npz,
    mesh_name,
)
from liverviz.ledger import Ledger
from liverviz.report import ROOT, header

RESULTS = ROOT / "bench" / "results" / "tradeoff_surrogate"
DOCS = ROOT / "docs"
SPY = ROOT / ".venv-solver" / "bin" / "python"
BASE_SCENE = ROOT / "data_spec" / "scenes" / "scene1_base.toml"

N_TEST = 50          # held-out simulations: the last N_TEST of the learning-curve dataset
N_LEARN = 400        # largest training set of the learning curve
N_BUDGET = 120       # simulations per mesh of the error budget (10 % held out for early stopping)
N_KNOB = 100         # training simulations of the network-size and node-fraction rows
LEARN_DATA = mesh_name(2, 16.0)  # the shipped scene 1: P2 on a 16 mm mesh
PAPER1 = [500, 300, 100, 50]
NETS = {"paper scene 1": PAPER1, "paper scenes 2-3": [500, 500, 300, 100, 50],
        "paper scene 4": [500] * 5, "128x3": [128, 128, 128], "64x2": [64, 64],
        "32x2": [32, 32]}
EPOCHS = 60          # cap (early stopping after 6 epochs without improvement ends most sooner)
LATENCY_CALLS = 200


def scene_text(degree: int, h: float, n: int) -> str:
    """Scene 1 with another element, mesh size and number of simulations (same seed, load
    draws and material)."""
    out = []
    section = None
    for line in BASE_SCENE.read_text().splitlines():
        s = line.strip()
        if s.startswith("["):
            section = s
        key = s.split("=")[0].strip() if "=" in s and not s.startswith("#") else None
        if section == "[scene]" and key == "name":
            line = f'name = "tradeoff_{mesh_name(degree, h)}"'
        elif section == "[scene]" and key == "n_simulations":
            line = f"n_simulations = {n}"
        elif section == "[geometry]" and key == "mesh_size":
            line = f"mesh_size = {h!r}"
        elif section == "[solver]" and key == "degree":
            line = f"degree = {degree}"
        out.append(line)
    return "\n".join(out) + "\n"


def datasets() -> dict[str, tuple[Path, Path]]:
    """name -> (scene file, dataset directory) of every dataset of the study."""
    out = {}
    for degree, h in BUDGET_MESHES:
        name = mesh_name(degree, h)
        n = N_LEARN + N_TEST if name == LEARN_DATA else N_BUDGET
        scene = RESULTS / "scenes" / f"{name}.toml"
        scene.parent.mkdir(parents=True, exist_ok=True)
        text = scene_text(degree, h, n)
        if not scene.exists() or scene.read_text() != text:
            scene.write_text(text)
        out[name] = (scene, RESULTS / "data" / name)
    return out


def complete(scene: Path, out: Path) -> bool:
    """Every simulation of the scene has its shard in ``out``."""
    from data_spec import list_shards, load_scene

    return out.exists() and len(list_shards(out)) >= load_scene(scene).n_simulations


def generate(nranks: int) -> None:
    """Generate (or finish) every dataset with ``mpirun -n nranks fem_sim generate``."""
    env = mpirun_env()
    for name, (scene, out) in datasets().items():
        print(f"== dataset {name}: {out}", file=sys.stderr, flush=True)
        subprocess.run(["mpirun", "-n", str(nranks), str(SPY), "-m", "fem_sim", "generate",
                        str(scene), "--out", str(out)], check=True, env=env)


# ----------------------------------------------------------------------------------------------
# The trainings
# ----------------------------------------------------------------------------------------------
def plan() -> list[dict]:
    """Every training of the study; each changes one knob from the paper's scene-1 network."""
    runs = []

    def add(group, **kw):
        spec = {"data": LEARN_DATA, "n_train": N_KNOB, "hidden": PAPER1, "node_fraction": 0.25,
                "nodes": "all", **kw}
        spec["id"] = "-".join(str(spec[k]).replace(" ", "") for k in
                              ("data", "n_train", "hidden", "node_fraction", "nodes"))
        if spec["id"] not in {r["id"] for r in runs}:
            runs.append({"group": group, **spec})
        else:  # the same training serves several groups
            next(r for r in runs if r["id"] == spec["id"]).setdefault("also", []).append(group)

    for n in (25, 50, 100, 200, N_LEARN):
        add("training simulations", n_train=n)
    for hidden in NETS.values():
        add("network", hidden=hidden)
    for frac in (0.05, 0.1, 0.25, 1.0):
        add("node fraction", node_fraction=frac)
    add("surface only", n_train=N_LEARN, nodes="surface")
    for degree, h in BUDGET_MESHES:
        add("error budget", data=mesh_name(degree, h), n_train=N_BUDGET)
    return runs


RUNS = Ledger(RESULTS / "runs.jsonl", key="id")
LATENCIES = Ledger(RESULTS / "latency.jsonl", key="id")


_DATA: dict[str, object] = {}


def dataset(name: str):
    """The dataset ``name`` (read once per process) and its surface node ids."""
    from data_spec import read_geometry
    from data_spec.shards import geometry_path
    from surrogate.data import load_dataset

    if name not in _DATA:
        d = RESULTS / "data" / name
        ds = load_dataset(d, stream=False)
        surface = read_geometry(geometry_path(d, ds.geo_ids[0])).surface_nodes
        _DATA[name] = (ds, surface)
    return _DATA[name]


def test_samples(ds) -> np.ndarray:
    return np.flatnonzero(ds.sample_sim >= N_LEARN)


def evaluate(model_dir: Path, ds, samples: np.ndarray, nodes=None, dtype="float32") -> dict:
    """Metrics of the exported model (through the real inference path) on ``samples``, at
    ``nodes`` (default: all output nodes)."""
    from surrogate import load_predictor
    from surrogate.metrics import displacement_metrics

    predict = load_predictor(model_dir, dtype=dtype)
    out = ds.out_nodes[0]
    keep = np.arange(out.size) if nodes is None else np.flatnonzero(np.isin(out, nodes))
    preds, trues = [], []
    for chunk in np.array_split(samples, max(1, samples.size // 100)):
        p = predict(ds.forces[chunk], ds.load_nodes[chunk], nodes=out[keep])
        preds.append(p.reshape(-1, 3))
        trues.append(np.concatenate([ds.targets[ds.sample_offset[s]:ds.sample_offset[s + 1]]
                                     [keep] for s in chunk]))
    return displacement_metrics(np.concatenate(preds), np.concatenate(trues))


def train_one(spec: dict) -> dict:
    """Train one network on its training simulations, export it, and measure it on the
    held-out simulations (all nodes and surface nodes; float32)."""
    from surrogate.config import get_config
    from surrogate.data import restrict_nodes
    from surrogate.export import export_model
    from surrogate.metrics import displacement_metrics
    from surrogate.nodewise import example_index
    from surrogate.train import fit_design

    ds, surface = dataset(spec["data"])
    train_ds = restrict_nodes(ds, [surface]) if spec["nodes"] == "surface" else ds
    train = np.flatnonzero(train_ds.sample_sim < spec["n_train"])
    cfg = get_config("paper_scene1", hidden=spec["hidden"], node_fraction=spec["node_fraction"],
                     epochs=EPOCHS, final_fit=False)
    t0 = time.perf_counter()
    trained, hist = fit_design(train_ds, train, cfg, 0, f"{spec['id']} ",
                               lambda m: print(m, file=sys.stderr, flush=True))
    seconds = time.perf_counter() - t0
    model = RESULTS / "models" / spec["id"]
    export_model(model, trained, cfg, train_ds)
    rec = {"id": spec["id"], "spec": spec, "training_seconds": seconds, "epochs": len(hist),
           "examples_seen": int(sum(h["examples_per_s"] * h["seconds"] for h in hist))}
    if spec["data"] == LEARN_DATA:
        test = test_samples(ds)
        _, _, tgt = example_index(ds, train)
        mean = ds.targets[tgt].mean(axis=0)
        _, _, ttgt = example_index(ds, test)
        true = ds.targets[ttgt]
        rec["naive_mee"] = displacement_metrics(np.broadcast_to(mean, true.shape), true)["mee"]
        rec["all"] = evaluate(model, ds, test)
        rec["surface"] = evaluate(model, ds, test, nodes=surface)
        if spec["n_train"] == N_LEARN or "network" in [spec["group"], *spec.get("also", [])]:
            for dtype in ("bfloat16", "float16"):
                rec[f"all_{dtype}"] = evaluate(model, ds, test, dtype=dtype)
    return rec


def latency(model_dir: Path, nodes, dtype: str, calls: int) -> float:
    """Median seconds of one jitted call for one load case, after warm-up."""
    from surrogate import load_predictor
    from surrogate.latency import latency as timed_calls

    return timed_calls(load_predictor(model_dir, dtype=dtype), nodes, calls)[0]


def study(part: int, parts: int) -> None:
    from tqdm import tqdm

    done = RUNS.records()
    ready = {name for name, (scene, out) in datasets().items() if complete(scene, out)}
    todo = [r for i, r in enumerate(plan()) if i % parts == part and r["id"] not in done]
    waiting = [r["id"] for r in todo if r["data"] not in ready]
    if waiting:
        print(f"not trained (dataset incomplete; run without --part to generate): {waiting}",
              file=sys.stderr)
    todo = [r for r in todo if r["data"] in ready]
    bar = tqdm(todo, desc=f"tradeoff-surrogate {part + 1}/{parts}", unit="training")
    for spec in bar:
        bar.set_postfix_str(spec["id"])
        RUNS.add(train_one(spec))


def latencies() -> None:
    """Latency of every exported model (all nodes and surface nodes; float32, and 16 bits for
    the rows that have it). Run alone: other work on the cores inflates it."""
    done = LATENCIES.records()
    for rec in RUNS.records().values():
        spec = rec["spec"]
        if rec["id"] in done or spec["data"] != LEARN_DATA:
            continue
        _, surface = dataset(LEARN_DATA)
        model = RESULTS / "models" / rec["id"]
        out = {"id": rec["id"]}
        for dtype in ("float32", "bfloat16", "float16"):
            if dtype != "float32" and f"all_{dtype}" not in rec:
                continue
            out[f"all_{dtype}"] = latency(model, None, dtype, LATENCY_CALLS)
            out[f"surface_{dtype}"] = latency(model, surface, dtype, LATENCY_CALLS)
        LATENCIES.add(out)


# ----------------------------------------------------------------------------------------------
# The error budget
# ----------------------------------------------------------------------------------------------
EXCLUDE = 32.0  # mm: errors are measured outside this ball around the load point (2 x the
                # coarsest h; a point load has no converged limit next to the load), on every mesh


def simulation_seconds(name: str, n: int) -> float:
    """Solver seconds of ``n`` simulations of dataset ``name`` (the mean over its shards; one
    rank each: CPU-seconds)."""
    from data_spec import list_shards, read_shard

    per = [read_shard(p).stats.wall_time.sum() for p in list_shards(RESULTS / "data" / name)]
    return float(np.mean(per) * n)


@functools.cache
def _ref_offsets(k: int) -> dict:
    """Where each mesh's vertices start in case k's reference values (MESHES order)."""
    sizes = []
    for d2, h2 in BUDGET_MESHES:
        with np.load(budget_npz(k, d2, h2)) as z:
            sizes.append(z["nodes"].shape[0])
    return dict(zip(BUDGET_MESHES, np.cumsum([0, *sizes[:-1]])))


def _case_errors(k, case, degree, h, ds, predict, fem) -> dict | None:
    """FE, surrogate and total node errors of load case k on mesh (degree, h); None when a
    solve is missing."""
    ref_rec, rec = fem.get((k, *BUDGET_REFERENCE)), fem.get((k, degree, h))
    if not (ref_rec and rec and ref_rec["status"] == "ok" and rec["status"] == "ok"):
        return None
    with np.load(budget_npz(k, degree, h)) as z:
        u, pts = z["u_nodes"], z["nodes"]
    if pts.shape != ds.points[0].shape or not np.allclose(pts, ds.points[0]):
        raise RuntimeError(f"{mesh_name(degree, h)}: the budget's mesh is not the dataset's")
    start = _ref_offsets(k)[(degree, h)]
    with np.load(budget_npz(k, *BUDGET_REFERENCE)) as z:
        u_ref = z["u"][start:start + pts.shape[0]]
        scale = np.abs(z["u_nodes"]).max()
        # Each mesh loads its node nearest to the case's point: how far apart the loaded
        # points of this mesh and of the reference are.
        offset = np.linalg.norm(pts[rec["load_node"]] - z["nodes"][ref_rec["load_node"]])
    s = predict(np.asarray([case["force"]]), [rec["load_node"]])
    far = np.linalg.norm(pts - np.asarray(case["point"]), axis=1) > EXCLUDE
    fe, sur, tot = (np.linalg.norm(a - b, axis=1) for a, b in
                    ((u, u_ref), (s, u), (s, u_ref)))
    return {"fe": fe[far], "sur": sur[far], "tot": tot[far], "fe_all": fe, "tot_all": tot,
            "scale": scale, "offset": offset}


def budget() -> list[dict]:
    """Per budget mesh: FE error against the reference, surrogate error against its own FE
    answer, and the surrogate's error against the reference (the sum a user gets), on the
    budget's load cases at full load, at the mesh's vertices outside EXCLUDE of the load."""
    from surrogate import load_predictor

    fem = BUDGET_RUNS.records()
    if not (BUDGET_RESULTS / "cases.json").exists():
        return []
    cases = json.loads((BUDGET_RESULTS / "cases.json").read_text())
    trained = {r["spec"]["data"]: r for r in RUNS.records().values()
               if r["spec"]["group"] == "error budget" or "error budget" in
               r["spec"].get("also", [])}
    rows = []
    for degree, h in sorted(BUDGET_MESHES, key=lambda m: (m[0], -m[1])):  # P1 then P2, coarse first
        name = mesh_name(degree, h)
        if name not in trained:
            continue
        ds, _ = dataset(name)
        predict = load_predictor(RESULTS / "models" / trained[name]["id"])
        per = [e for k, case in enumerate(cases)
               if (e := _case_errors(k, case, degree, h, ds, predict, fem)) is not None]
        if not per:
            continue

        def cat(key, per=per):
            return np.concatenate([e[key] for e in per])

        rows.append({"mesh": name, "degree": degree, "h": h, "vertices": ds.points[0].shape[0],
                     "cases": len(per), "fe": float(cat("fe").mean()),
                     "surrogate": float(cat("sur").mean()), "total": float(cat("tot").mean()),
                     "fe_p95": float(np.percentile(cat("fe"), 95)),
                     "total_p95": float(np.percentile(cat("tot"), 95)),
                     "fe_all": float(cat("fe_all").mean()),
                     "total_all": float(cat("tot_all").mean()),
                     "u_ref_max": float(np.mean([e["scale"] for e in per])),
                     "offset": float(np.mean([e["offset"] for e in per])),
                     "sim_hours": simulation_seconds(name, N_BUDGET) / 3600,
                     "train_hours": trained[name]["training_seconds"] / 3600,
                     "sims": N_BUDGET})
    return rows


# ----------------------------------------------------------------------------------------------
# The report
# ----------------------------------------------------------------------------------------------
def n_params(hidden: list[int], dim: int = 13) -> int:
    widths = [dim, *hidden, 3]
    return sum(a * b + b for a, b in zip(widths[:-1], widths[1:]))


def _groups(r) -> list:
    return [r["spec"]["group"], *r["spec"].get("also", [])]


def _m(r, key="all") -> str:
    x = r[key]
    return f"{x['mee']:.3f} | {x['ee_p95']:.3f} | {x['pct_ee_lt_1mm']:.1f}"


def _ms(lat: dict, r, key) -> str:
    v = lat.get(r["id"], {}).get(key)
    return f"{1e3 * v:.2f}" if v is not None else "-"


NAME_OF = {tuple(v): k for k, v in NETS.items()}


def _intro(ds_note: str) -> list[str]:
    return [*header("Surrogate price list and the error budget").rstrip().split("\n"),
            "The FE error budget comes first from `bench/budget_fem.py` (`make "
            "tradeoff-surrogate` runs both).", "",
            f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
            "JAX on the CPU. Training seconds are single runs while another training or "
            "simulation shared the 2 cores (expect 10-30 % noise); latencies are medians of "
            f"{LATENCY_CALLS} jitted calls for one load case, measured with nothing else "
            "running.", "",
            f"Data: scene 1 (`data_spec/scenes/scene1_base.toml`: the phantom liver, P2 on a "
            f"16 mm mesh, one random 0.4 N nodal force, 10 load steps): {ds_note}. Every "
            "network is trained on the first N simulations (10 % of them held out for early "
            f"stopping) and measured on the same {N_TEST} held-out simulations (all their load "
            "steps), through the exported predictor. Unless the row changes it: the paper's "
            f"scene-1 network {tuple(PAPER1)}, {N_KNOB} training simulations, node fraction "
            f"0.25, float32, at most {EPOCHS} epochs. MEE: mean Euclidean error (mm); p95: its "
            "95th percentile; < 1 mm: % of node errors under 1 mm; skill: MEE / MEE of the "
            "naive mean-displacement predictor (paper, scene 1: 0.078).", ""]


def _curve_and_networks(rows, lat, ds_note) -> tuple[list[str], list, list]:
    L = ["## Training simulations (learning curve)", "",
         "| training sims | MEE mm | p95 mm | < 1 mm % | skill | training s | epochs |",
         "|---|---|---|---|---|---|---|"]
    lc = sorted((r for r in rows if "training simulations" in _groups(r)),
                key=lambda r: r["spec"]["n_train"])
    for r in lc:
        L.append(f"| {r['spec']['n_train']} | {_m(r)} | {r['all']['mee'] / r['naive_mee']:.3f} "
                 f"| {r['training_seconds']:.0f} | {r['epochs']} |")
    L += ["", "## Network size", "",
          f"Latency: one load case, all {ds_note.split(' ')[0] if ds_note else ''} nodes / "
          "surface nodes only, float32.", "",
          "| network | hidden | parameters | MEE mm | p95 mm | < 1 mm % | training s | "
          "latency all ms | latency surface ms |", "|---|---|---|---|---|---|---|---|---|"]
    nets = sorted((r for r in rows if "network" in _groups(r)),
                  key=lambda r: -n_params(r["spec"]["hidden"]))
    for r in nets:
        hid = r["spec"]["hidden"]
        L.append(f"| {NAME_OF.get(tuple(hid), '')} | {tuple(hid)} | {n_params(hid):,} | "
                 f"{_m(r)} | {r['training_seconds']:.0f} | {_ms(lat, r, 'all_float32')} | "
                 f"{_ms(lat, r, 'surface_float32')} |")
    return L, lc, nets


def _fraction_and_precision(rows, lat) -> list[str]:
    L = ["", "## Sampled node fraction per epoch", "",
         "| node fraction | MEE mm | p95 mm | < 1 mm % | training s | examples seen |",
         "|---|---|---|---|---|---|"]
    for r in sorted((r for r in rows if "node fraction" in _groups(r)),
                    key=lambda r: r["spec"]["node_fraction"]):
        L.append(f"| {r['spec']['node_fraction']:g} | {_m(r)} | {r['training_seconds']:.0f} | "
                 f"{r['examples_seen']:,} |")
    L += ["", "## Inference precision", "",
          "The float32-trained weights cast to 16 bits (`load_predictor(dir, dtype=...)`). "
          "XLA on this CPU has no native 16-bit matrix units: the latency column says whether "
          "it pays here.", "",
          "| network | training sims | precision | MEE mm | p95 mm | < 1 mm % | MEE change | "
          "latency all ms | latency surface ms |", "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted((r for r in rows if "all_float16" in r and r["spec"]["nodes"] == "all"),
                    key=lambda r: (-n_params(r["spec"]["hidden"]), -r["spec"]["n_train"])):
        hid = tuple(r["spec"]["hidden"])
        for dt in ("float32", "bfloat16", "float16"):
            key = "all" if dt == "float32" else f"all_{dt}"
            change = r[key]["mee"] / r["all"]["mee"] - 1
            L.append(f"| {NAME_OF.get(hid, hid)} | {r['spec']['n_train']} | {dt} | "
                     f"{_m(r, key)} | {change:+.1%} | {_ms(lat, r, f'all_{dt}')} | "
                     f"{_ms(lat, r, f'surface_{dt}')} |")
    return L


def _surface(rows, lat) -> list[str]:
    L = ["", "## All nodes against the surface only", "",
         "The paper notes that an application needs the visible surface only. A model "
         "trained on all nodes and evaluated on the surface nodes, against one trained on "
         "the surface nodes only.", "",
         "| trained on | training sims | evaluated on | MEE mm | p95 mm | < 1 mm % | "
         "training s | latency ms |", "|---|---|---|---|---|---|---|---|"]
    for r in sorted((r for r in rows if r["spec"]["n_train"] == N_LEARN and
                     r["spec"]["hidden"] == PAPER1), key=lambda r: r["spec"]["nodes"]):
        trained_on = r["spec"]["nodes"]
        for where in (["all", "surface"] if trained_on == "all" else ["surface"]):
            L.append(f"| {trained_on} nodes | {N_LEARN} | {where} nodes | {_m(r, where)} | "
                     f"{r['training_seconds']:.0f} | {_ms(lat, r, where + '_float32')} |")
    return L


def _budget_section(b: list) -> list[str]:
    L = ["", "## Error budget: the FE mesh against the surrogate", "",
         f"For each mesh, a dataset of scene 1 on it ({N_BUDGET} simulations), the paper's "
         f"scene-1 network trained on it, and {BUDGET_CASES} new load cases drawn by scene "
         "1's rule (`bench/budget_fem.py`), solved on that mesh "
         "and on the reference (P2 on a 6 mm mesh, as in `docs/tradeoff_fem.md`). At the "
         f"mesh's vertices more than {EXCLUDE:g} mm from the load point (a point load has no "
         "converged limit next to it), at full load: the FE error (mesh against reference), "
         "the surrogate's error (network against the FE answer of its own mesh: what "
         "training reports), and the total (network against the reference: what a user "
         "gets). Cost: solver CPU-hours of the dataset plus training hours (this machine; "
         "both measured while up to five processes shared the two cores, so up to ~2.5x "
         "what they cost alone). "
         "Each mesh loads its node nearest to the case's point (the load offset column: how "
         "far that node is from the reference's). A point load has no converged limit, and "
         "with this stiffening material the far field too depends on how a mesh resolves "
         "the load: the FE column is the error of each mesh for this scene's loads; "
         "`docs/tradeoff_fem.md` gives the elements' error under a patch load.",
         "", "| mesh | vertices | FE error mm | surrogate error mm | total mm | total p95 mm "
         "| FE error, all nodes mm | total, all nodes mm | mean max u_ref mm | load offset "
         "mm | simulation CPU-h | training h |", "|" + "---|" * 12]
    for r in b:
        L.append(f"| P{r['degree']} {r['h']:g} mm | {r['vertices']} | {r['fe']:.3f} | "
                 f"{r['surrogate']:.3f} | {r['total']:.3f} | {r['total_p95']:.3f} | "
                 f"{r['fe_all']:.3f} | {r['total_all']:.3f} | {r['u_ref_max']:.1f} | "
                 f"{r['offset']:.1f} | {r['sim_hours']:.3f} | {r['train_hours']:.3f} |")
    return L


def report() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = RUNS.records()
    lat = LATENCIES.records()
    rows = [r for r in runs.values() if "all" in r]
    ds_note = ""
    if (RESULTS / "data" / LEARN_DATA).exists():
        ds, surface = dataset(LEARN_DATA)
        n_sims = np.unique(ds.sample_sim).size
        ds_note = (f"{ds.points[0].shape[0]} nodes ({surface.size} on the surface), "
                   f"{n_sims} simulations x {ds.n_samples // max(1, n_sims)} load steps")
    curve, lc, nets = _curve_and_networks(rows, lat, ds_note)
    b = budget()
    L = (_intro(ds_note) + curve + _fraction_and_precision(rows, lat) + _surface(rows, lat)
         + _budget_section(b))
    DOCS.mkdir(exist_ok=True)
    (DOCS / "tradeoff_surrogate.md").write_text("\n".join(L) + "\n")
    plots(lc, nets, rows, lat, b, plt)
    print(f"wrote {DOCS / 'tradeoff_surrogate.md'}, {DOCS / 'tradeoff_surrogate.png'} and "
          f"{DOCS / 'error_budget.png'}")


def _plot_curve(ax, lc, plt) -> None:
    n = [r["spec"]["n_train"] for r in lc]
    ax.plot(n, [r["all"]["mee"] for r in lc], "o-", label="MEE")
    ax.plot(n, [r["all"]["ee_p95"] for r in lc], "s--", label="95th percentile")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(n, [str(v) for v in n])
    ax.xaxis.set_minor_formatter(plt.NullFormatter())
    ax.set_xlabel("training simulations")
    ax.set_ylabel("error on held-out simulations (mm)")
    ax.set_title("learning curve (paper scene-1 net)")
    ax.legend()


def _plot_networks(ax, nets, lat) -> None:
    for r in nets:
        t = lat.get(r["id"], {}).get("all_float32")
        if t is None:
            continue
        ax.scatter(1e3 * t, r["all"]["mee"], color="C0")
        ax.annotate(NAME_OF.get(tuple(r["spec"]["hidden"]), ""), (1e3 * t, r["all"]["mee"]),
                    textcoords="offset points", xytext=(4, 3), fontsize=8)
        ts = lat[r["id"]].get("surface_float32")
        ax.scatter(1e3 * ts, r["surface"]["mee"], color="C1", marker="^")
    ax.scatter([], [], color="C0", label="all nodes")
    ax.scatter([], [], color="C1", marker="^", label="surface nodes")
    for hz in (300, 1000):
        ax.axvline(1e3 / hz, color="grey", ls=":", lw=1)
        ax.text(1e3 / hz, ax.get_ylim()[1] if nets else 1, f" {hz} Hz", fontsize=7, va="top")
    ax.set_xscale("log")
    ax.set_xlabel("latency per load case (ms, float32)")
    ax.set_ylabel("MEE (mm)")
    ax.set_title(f"network size ({N_KNOB} training sims)")
    ax.legend(fontsize=8)


def _plot_fractions(ax, rows) -> None:
    fr = sorted((r for r in rows if "node fraction" in _groups(r)),
                key=lambda r: r["spec"]["node_fraction"])
    for r in fr:
        ax.scatter(r["training_seconds"], r["all"]["mee"], color="C2")
        ax.annotate(f"{r['spec']['node_fraction']:g}", (r["training_seconds"],
                    r["all"]["mee"]), textcoords="offset points", xytext=(4, 3), fontsize=8)
    ax.set_xlabel("training seconds")
    ax.set_ylabel("MEE (mm)")
    ax.set_title("sampled node fraction per epoch")


def _plot_budget(b, plt) -> None:
    fig, ax = plt.subplots(figsize=(9, 5))
    if b:
        x = np.arange(len(b))
        w = 0.27
        ax.bar(x - w, [r["fe"] for r in b], w, label="FE error (mesh vs reference)")
        ax.bar(x, [r["surrogate"] for r in b], w, label="surrogate error (vs its own FE data)")
        ax.bar(x + w, [r["total"] for r in b], w, label="total (surrogate vs reference)")
        ax.scatter(x + w, [r["fe"] + r["surrogate"] for r in b], marker="_", s=400,
                   color="k", label="FE + surrogate (upper bound)", zorder=3)
        ax.set_xticks(x, [f"P{r['degree']} {r['h']:g} mm\n{r['vertices']} nodes\n"
                          f"{r['sim_hours'] + r['train_hours']:.2f} h" for r in b])
        ax.set_yscale("log")
        ax.set_ylabel(f"mean error, mm (outside {EXCLUDE:g} mm of the load)")
        ax.set_title("error budget, scene 1 on the phantom; under each mesh: cost "
                     "(simulation CPU-h + training h)", fontsize=10)
        ax.legend(fontsize=8)
        ax.grid(True, axis="y", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(DOCS / "error_budget.png", dpi=110)
    plt.close(fig)


def plots(lc, nets, rows, lat, b, plt) -> None:
    fig, ax = plt.subplots(1, 3, figsize=(17, 5))
    if lc:
        _plot_curve(ax[0], lc, plt)
    _plot_networks(ax[1], nets, lat)
    _plot_fractions(ax[2], rows)
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(DOCS / "tradeoff_surrogate.png", dpi=110)
    plt.close(fig)
    _plot_budget(b, plt)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--np", type=int, default=2, help="MPI ranks for dataset generation")
    ap.add_argument("--generate-only", action="store_true")
    ap.add_argument("--part", default="1/1", help="I/N: run every N-th training from the I-th "
                    "(two processes can share the study)")
    ap.add_argument("--report", action="store_true", help="only write the report")
    a = ap.parse_args()
    if not a.report:
        i, n = (int(x) for x in a.part.split("/"))
        if n == 1 or a.generate_only:  # parts share the datasets: one process makes them
            generate(a.np)
        if a.generate_only:
            return 0
        study(i - 1, n)
        if a.part == "1/1":
            latencies()
    report()
    return 0


if __name__ == "__main__":
    sys.exit(main())
