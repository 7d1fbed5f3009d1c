"""docs/demo.md: what `make demo` did on this machine (run by scripts/demo.sh at its end).

Usage: .venv-train/bin/python scripts/demo_report.py --data DIR --run RUN
--generate-seconds S --total-seconds T [--md docs/demo.md]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from data_spec import list_shards, load_scene, read_shard
from liverviz.report import ROOT, capture
from surrogate.metrics import metrics_table


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--run", type=Path, required=True)
    ap.add_argument("--generate-seconds", type=float, required=True)
    ap.add_argument("--total-seconds", type=float, required=True)
    ap.add_argument("--md", type=Path, default=ROOT / "docs" / "demo.md")
    a = ap.parse_args()
    scene = load_scene(a.data / "scene.toml")
    shards = [read_shard(p) for p in list_shards(a.data)]
    ok = [s for s in shards if s.status == "ok"]
    its = [i for s in ok for i in s.stats.newton_iterations]
    m = json.loads((a.run / "metrics.json").read_text())
    with capture(a.md, "make demo"):
        print(f"Scene `{scene.name}`: {len(shards)} simulations ({len(shards) - len(ok)} "
              f"failed), {ok[0].displacement.shape[1]:,} nodes, "
              f"{ok[0].displacement.shape[0]} load steps, mean "
              f"{sum(its) / max(len(its), 1):.2f} Newton iterations per load step; generated "
              f"in {a.generate_seconds:.0f} s with mpirun.\n")
        print(f"Surrogate: config `{json.loads((a.run / 'config.json').read_text())['name']}`, "
              f"{m['folds']}-fold cross-validation by simulation, "
              f"{m['training_seconds']:.0f} s of training; metrics on the held-out folds:\n")
        print(metrics_table({"network": m["network"], "naive (mean displacement)": m["naive"]}))
        print(f"\nskill = MEE_NN / MEE_naive = {m['skill']:.3f}; the whole demo, set-up cached, "
              f"{a.total_seconds:.0f} s.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
