"""The training engine against a baseline checkout, side by side: the same dataset and config
trained by both, runs interleaved (they share the machine's load), median wall time,
training throughput and the cross-validated MEE of each.

    .venv-train/bin/python bench/bench_engine.py --baseline WORKTREE --data runs/demo/data \
        [--baseline-data DIR] [--runs 3] [--md docs/engine.md] [key=value ...]

WORKTREE is a checkout of the baseline commit (``git worktree add /tmp/base COMMIT``); it runs
in this environment with WORKTREE first on PYTHONPATH. ``--baseline-data``: a copy of the
dataset whose scene.toml the baseline can read (scene keys may have been renamed since).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from report import ROOT, capture  # noqa: E402


def train(code: Path | None, data: Path, run: Path, overrides: list[str]) -> dict:
    env = dict(os.environ)
    if code is not None:
        env["PYTHONPATH"] = str(code)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "surrogate", "train", "--data", str(data.resolve()),
                    "--run",
                    str(run), *overrides], env=env, check=True, capture_output=True,
                   cwd=tempfile.gettempdir())
    m = json.loads((run / "metrics.json").read_text())
    return {"wall": time.perf_counter() - t0, "mee": m["network"]["mee"],
            "skill": m["skill"], "rate": m["training_examples_per_s"]}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", type=Path, required=True)
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--baseline-data", type=Path)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--md", default=str(ROOT / "docs" / "engine.md"))
    ap.add_argument("overrides", nargs="*",
                    default=["epochs=12", "folds=2", "final_fit=false", "early_stopping=100"])
    a = ap.parse_args()
    base_commit = subprocess.run(["git", "-C", str(a.baseline), "rev-parse", "--short", "HEAD"],
                                 capture_output=True, text=True).stdout.strip()
    res = {"baseline": [], "this code": []}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(a.runs):
            res["baseline"].append(train(a.baseline, a.baseline_data or a.data,
                                         Path(tmp) / f"b{k}", a.overrides))
            res["this code"].append(train(None, a.data, Path(tmp) / f"n{k}", a.overrides))
    with capture(a.md, "Training engine against a baseline"):
        print(f"Dataset `{a.data}`, overrides `{' '.join(a.overrides)}`, {a.runs} runs of each, "
              f"interleaved; baseline {base_commit}. Wall time includes start-up, data loading "
              "and compilation; throughput is the trainer's own figure (examples per second of "
              "training epochs).\n")
        print("| code | wall s (median) | x baseline | training examples/s (median) | MEE mm | "
              "skill |\n|---|---|---|---|---|---|")
        wb = np.median([r["wall"] for r in res["baseline"]])
        for name, rs in res.items():
            w = np.median([r["wall"] for r in rs])
            print(f"| {name} | {w:.1f} | {w / wb:.2f} | "
                  f"{np.median([r['rate'] for r in rs]):,.0f} | {rs[0]['mee']:.4f} | "
                  f"{rs[0]['skill']:.4f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
