"""Batch throughput of `fem_sim generate` with mpirun -n 1 and -n 2 (R = 1) on the small
scene-1 variant: simulations per hour (median of --runs), and the ratio n2 / n1.

    .venv-solver/bin/python bench/bench_throughput.py [--sims 40] [--runs 3]
        [--md docs/throughput.md]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from fem_sim.batch.chunked import mpirun_env
from liverviz.report import capture

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "data_spec" / "scenes" / "demo_scene1.toml"
ENV = mpirun_env(oversubscribe=False)


def run(n: int, sims: int) -> float:
    with tempfile.TemporaryDirectory() as d:
        out = subprocess.run(["mpirun", "-n", str(n), sys.executable, "-m", "fem_sim",
                              "generate", str(SCENE), "--out", d, "--only", f"0..{sims}",
                              "--no-progress"], env=ENV, capture_output=True, text=True,
                             check=True).stdout
    return float(re.search(r"(\d+) simulations/hour", out).group(1))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sims", type=int, default=40)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--md", default=str(ROOT / "docs" / "throughput.md"))
    a = ap.parse_args()
    rates = {n: [] for n in (1, 2)}
    for _ in range(a.runs):  # interleaved: both rank counts share the machine's load
        for n in rates:
            rates[n].append(run(n, a.sims))
    with capture(a.md, "Batch throughput: mpirun -n 2 against -n 1"):
        report(a, rates)


def report(a, rates):
    print(f"scene {SCENE.name}, {a.sims} simulations per run, median of {a.runs} runs "
          "(wall time includes start-up, meshing and form compilation)\n")
    print("| ranks | simulations/hour (median) | runs |\n|---|---|---|")
    for n, r in rates.items():
        print(f"| {n} | {np.median(r):.0f} | {', '.join(f'{x:.0f}' for x in r)} |")
    print(f"\nthroughput ratio -n 2 / -n 1: {np.median(rates[2]) / np.median(rates[1]):.2f} "
          "(target >= 1.8)")


if __name__ == "__main__":
    main()
