"""Surrogate inference latency and training throughput on this CPU.

    .venv-train/bin/python bench/bench_surrogate.py [--calls 200] [--md docs/inference.md]

Latency: median of --calls jitted predictor calls (after warm-up) through the real exported
model path (load_predictor), for the whole liver and for the surface only, at the paper's
network sizes. Weights are random: latency does not depend on their values.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np

from liverviz.report import ROOT, capture
from surrogate import load_predictor
from surrogate.config import get_config
from surrogate.engine import make_train_step, optimizer
from surrogate.export import export_model
from surrogate.features import FeatureSpec
from surrogate.model import NodeMLP
from surrogate.nodewise import nodewise_loss
from surrogate.normalise import Normaliser

NETS = {"small (128,128,128)": [128, 128, 128],
        "paper scene 1 (500,300,100,50)": [500, 300, 100, 50],
        "paper scene 4 (500 x 5)": [500] * 5}


def fake_model(directory: Path, hidden, n_nodes: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-100, 100, size=(n_nodes, 3))
    fixed = np.arange(100)
    spec = FeatureSpec(n_loads=1)
    model = NodeMLP(hidden=tuple(hidden))
    params = jax.device_get(model.init(jax.random.PRNGKey(seed), jnp.zeros((1, spec.dim)))
                            ["params"])
    norm = Normaliser(x_mean=np.zeros(spec.dim, np.float32), x_std=np.ones(spec.dim, np.float32),
                       y_mean=np.zeros(3, np.float32), y_std=np.ones(3, np.float32))
    ds = SimpleNamespace(forces=np.full((1, 1, 3), 0.4), extra=np.zeros((1, 0)),
                         scene_name="bench", spec=spec, points=[pts], fixed=[fixed],
                         out_nodes=[np.arange(n_nodes)],
                         triangles=[np.zeros((0, 3), dtype=np.int64)])  # nothing to draw
    export_model(directory, (params, norm), get_config("small", hidden=hidden), ds)
    return pts


def latency(predict, n_nodes, nodes, calls):
    f = np.array([[0.0, 0.0, -0.4]])
    predict(f, [7], nodes=nodes)  # compile
    times = []
    for i in range(calls):
        f[0, 2] = -0.4 + 1e-4 * i
        t = time.perf_counter()
        predict(f, [7], nodes=nodes)
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--calls", type=int, default=200)
    ap.add_argument("--md", default=str(ROOT / "docs" / "inference.md"))
    args = ap.parse_args()
    with capture(args.md, "Surrogate inference latency and training throughput"):
        _run(args)


def _run(args):
    print(f"JAX {jax.__version__} on {jax.devices()[0].platform}, float32\n")
    print("| network | nodes | latency ms (median) | rate Hz | 25 Hz graphics | 300 Hz haptics |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, hidden in NETS.items():
            for n_nodes in (15400, 5000):
                d = Path(tmp) / f"{len(hidden)}_{hidden[0]}_{n_nodes}"
                fake_model(d, hidden, n_nodes)
                predict = load_predictor(d)
                for label, nodes in (("all", None),
                                     ("surface ~30%", np.arange(0, n_nodes, 3))):
                    t = latency(predict, n_nodes, nodes, args.calls)
                    n = n_nodes if nodes is None else nodes.size
                    print(f"| {name} | {n} ({label}) | {1e3 * t:.2f} | {1 / t:.0f} | "
                          f"{'yes' if t < 1 / 25 else 'no'} | {'yes' if t < 1 / 300 else 'no'} |")
    # training throughput: examples per second of train_step at the paper's scene-1 size
    print("\n| network | batch | training examples/s |\n|---|---|---|")
    for name, hidden in NETS.items():
        cfg = get_config("small", hidden=hidden)
        model = NodeMLP(hidden=tuple(hidden))
        params = model.init(jax.random.PRNGKey(0), jnp.zeros((1, 18)))["params"]
        tx = optimizer(cfg, 1)
        opt_state = tx.init(params)
        step = make_train_step(nodewise_loss(model, 0.0, 1), tx)
        n = 20000
        norm = Normaliser(x_mean=jnp.zeros(18), x_std=jnp.ones(18), y_mean=jnp.zeros(3),
                          y_std=jnp.ones(3))
        data = {"static": jnp.asarray(np.random.rand(n, 11), jnp.float32),
                "forces": jnp.ones((100, 1, 3)), "load_points": jnp.ones((100, 1, 3)),
                "extra": jnp.zeros((100, 0)), "norm": norm}
        B = cfg["batch_size"]
        rows = jnp.asarray(np.random.randint(0, n, B))
        smp = jnp.asarray(np.random.randint(0, 100, B))
        tgt = jnp.zeros((B, 3))
        value = jnp.float32(1.0)
        params, opt_state, loss = step(params, opt_state, data, (rows, smp, tgt),
                                       jax.random.PRNGKey(0), value)
        loss.block_until_ready()
        t = time.perf_counter()
        for i in range(20):
            params, opt_state, loss = step(params, opt_state, data, (rows, smp, tgt),
                                           jax.random.PRNGKey(i), value)
        loss.block_until_ready()
        print(f"| {name} | {B} | {20 * B / (time.perf_counter() - t):,.0f} |")


if __name__ == "__main__":
    main()
