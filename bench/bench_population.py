"""Scene 4's shape parametrisation on a 120-liver phantom population: staged CPD of the
template onto every liver, PCA, and the paper's Figure 9 (cumulative explained variance, IoU
and Dice of each liver against its reconstruction from n = 1..40 components), plus staged vs
plain CPD on 20 livers. Prints the timings and the table; writes
bench/results/population/population.{md,json,png} and the report docs/population.md (with
docs/population.png).

    .venv-solver/bin/python bench/bench_population.py [--livers 120] [--mesh-size 8]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from report import ROOT, capture  # noqa: E402

SCENE = """schema_version = 1
[scene]
name = "population_bench"
n_simulations = {n}
[geometry]
source = "population"
population_size = {n}
population_seed = 1000
pca_components = 27
mesh_size = {h}
[material]
c = [4.1e-3]
m = [10.06]
K_over_mu = 200.0
[loads]
magnitude = 0.4
"""


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--livers", type=int, default=120)
    ap.add_argument("--mesh-size", type=float, default=8.0)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "population"))
    ap.add_argument("--md", default=str(ROOT / "docs" / "population.md"))
    a = ap.parse_args()
    from fem_sim.batch.population_cli import run

    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "population_bench.toml"
        scene.write_text(SCENE.format(n=a.livers, h=a.mesh_size))
        code = run(scene, a.out, n_max=40, compare_plain=20, progress=False)
    if code == 0:
        md = Path(a.md)
        shutil.copy(Path(a.out) / "population.png", md.with_suffix(".png"))
        body = (Path(a.out) / "population.md").read_text()
        with capture(md, f"Scene-4 shape parametrisation: {a.livers} phantom livers"):
            print(body.split("\n", 1)[1] if body.startswith("# ") else body)
            print(f"\n![explained variance, IoU and Dice against components]({md.stem}.png)")
    return code


if __name__ == "__main__":
    sys.exit(main())
