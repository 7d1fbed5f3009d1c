"""Surrogate price list, measured on this software (docs/tradeoff_surrogate.md; its prose:
bench/templates/tradeoff_surrogate.md.j2): on scene 1 the node-wise MLP trained with one knob
changed at a time (training simulations, network size, node fraction, precision, all nodes or
the surface), on the same held-out simulations: MEE, p95, % under 1 mm, training seconds and
latency; and the error budget's network on each budget mesh (``bench/budget_fem.py``).

    make tradeoff-surrogate       # budget_fem.py (solver env), then this script (trainer env)
    .venv-train/bin/python bench/tradeoff_surrogate.py --report   # report only

Resumable: bench/results/tradeoff_surrogate/runs.jsonl, done trainings skipped.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from data_spec.scene_writer import relocated_scene, scene_toml
from fem_sim.batch.chunked import mpirun_env
from fem_sim.batch.knob_run import (
    BUDGET_MESHES,
    mesh_name,
)
from liverviz.ledger import Ledger
from liverviz.plots import surrogate_price_list
from liverviz.report import ROOT, header, render, sections

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
    """Scene 1 with another element, mesh size and number of simulations."""
    d = relocated_scene(BASE_SCENE)
    d["scene"].update(name=f"tradeoff_{mesh_name(degree, h)}", n_simulations=n)
    d["geometry"]["mesh_size"], d["solver"]["degree"] = h, degree
    return scene_toml(d)


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


def latency(model_dir: Path, nodes, dtype: str, calls: int) -> float:  # median s of a call
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


def n_params(hidden, dim: int = 13) -> int:
    widths = [dim, *hidden, 3]
    return sum(a * b + b for a, b in zip(widths[:-1], widths[1:]))


def _groups(r) -> list:
    return [r["spec"]["group"], *r["spec"].get("also", [])]


NAME_OF = {tuple(v): k for k, v in NETS.items()}


def report() -> None:
    lat = LATENCIES.records()
    rows = [r for r in RUNS.records().values() if "all" in r]
    ds_note = ""
    if (RESULTS / "data" / LEARN_DATA).exists():
        ds, surface = dataset(LEARN_DATA)
        n_sims = np.unique(ds.sample_sim).size
        ds_note = (f"{ds.points[0].shape[0]} nodes ({surface.size} on the surface), "
                   f"{n_sims} simulations x {ds.n_samples // max(1, n_sims)} load steps")
    lc = sorted((r for r in rows if "training simulations" in _groups(r)),
                key=lambda r: r["spec"]["n_train"])
    nets = sorted((r for r in rows if "network" in _groups(r)),
                  key=lambda r: -n_params(r["spec"]["hidden"]))
    fractions = sorted((r for r in rows if "node fraction" in _groups(r)),
                       key=lambda r: r["spec"]["node_fraction"])
    body = render(Path(__file__).parent / "templates" / "tradeoff_surrogate.md.j2",
                  lat=lat, lc=lc, nets=nets, ds_note=ds_note, tuple=tuple,
                  fractions=fractions,
                  precision=sorted((r for r in rows if "all_float16" in r
                                    and r["spec"]["nodes"] == "all"),
                                   key=lambda r: (-n_params(r["spec"]["hidden"]),
                                                  -r["spec"]["n_train"])),
                  surface=sorted((r for r in rows if r["spec"]["n_train"] == N_LEARN
                                  and r["spec"]["hidden"] == PAPER1),
                                 key=lambda r: r["spec"]["nodes"]),
                  machine=platform.processor() or platform.machine(), cores=os.cpu_count(),
                  calls=LATENCY_CALLS, n_test=N_TEST, paper1=tuple(PAPER1), n_knob=N_KNOB,
                  epochs=EPOCHS, n_learn=N_LEARN, name_of=NAME_OF, n_params=n_params)
    DOCS.mkdir(exist_ok=True)
    md = DOCS / "tradeoff_surrogate.md"   # the error budget's section is budget_fem.py's
    md.write_text(header("Surrogate price list and the error budget").rstrip() + "\n" + body
                  + ("\n" + sections(md) if sections(md) else ""))
    surrogate_price_list(lc, nets, fractions, lat, NAME_OF, N_KNOB,
                         DOCS / "tradeoff_surrogate.png")
    print(f"wrote {md} and {DOCS / 'tradeoff_surrogate.png'}")


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
