"""Regularising the population basis: scene 4's real-time design with one knob changed at a
time, on the same held-out livers, into docs/population_basis.md.

The population basis (``surrogate/population_basis.py``) is told each liver's shape
coefficients; with 8 simulations per liver it can learn the training livers by their
coefficients instead of how shape changes the field. Every variant here is trained on
``make table4``'s scene-4 dataset with the same split (8 folds by liver, the first evaluated:
all simulations of 1/8 of the livers held out) and no final fit; the report gives the held-out
MEE, the median liver's MEE, the skill and the training time of each. One fold and one seed:
differences of a few per cent are noise.

    .venv-train/bin/python bench/population_basis_study.py     # after make table4 T4="--scenes 4"

Resumable: a variant whose run holds metrics for the same config is not trained again.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from report import header  # noqa: E402

DATA = ROOT / "bench" / "results" / "table4" / "scene4_livers" / "data"
RESULTS = ROOT / "bench" / "results" / "population_basis_study"
SPLIT = {"folds": 8, "evaluate_folds": 1, "final_fit": False}
VARIANTS = {  # every knob named: the shipped config's defaults move
    "no regularisation": {"input_noise": 0.0, "l2": 0.0},
    "input noise 0.1": {"input_noise": 0.1, "l2": 0.0},
    "input noise 0.3 (shipped)": {"input_noise": 0.3, "l2": 0.0},
    "input noise 0.5": {"input_noise": 0.5, "l2": 0.0},
    "input noise 1.0": {"input_noise": 1.0, "l2": 0.0},
    "weight decay 1e-3": {"input_noise": 0.0, "l2": 1e-3},
    "hidden (64, 64)": {"input_noise": 0.0, "l2": 0.0, "hidden": [64, 64]},
    "input noise 0.3, weight decay 1e-3": {"input_noise": 0.3, "l2": 1e-3},
    "input noise 0.3, weight decay 1e-2": {"input_noise": 0.3, "l2": 1e-2},
    "input noise 0.3, hidden (64, 64)": {"input_noise": 0.3, "l2": 0.0, "hidden": [64, 64]},
    "input noise 0.3, hidden (512, 512)": {"input_noise": 0.3, "l2": 0.0,
                                           "hidden": [512, 512]},
    "input noise 0.3, 128 modes": {"input_noise": 0.3, "l2": 0.0, "modes": 128},
}


def run(name: str, overrides: dict) -> dict:
    """The variant's metrics (trained unless its run has them for this very config)."""
    from table4 import train

    run_dir = RESULTS / name.replace(" ", "_").replace("(", "").replace(")", "").replace(",", "")
    return train(DATA, run_dir, "population_basis", {**SPLIT, **overrides})


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=sorted(VARIANTS), default=list(VARIANTS))
    ap.add_argument("--md", default=str(ROOT / "docs" / "population_basis.md"))
    a = ap.parse_args()
    if not (DATA / "sims").is_dir():
        print(f"{DATA}: missing; run make table4 T4=\"--scenes 4\" first", file=sys.stderr)
        return 2
    rows = []
    for name in a.only:
        m = run(name, VARIANTS[name])
        pl = m["per_liver_mee"]
        rows.append(f"| {name} | `{VARIANTS[name] or '-'}` | {m['network']['mee']:.3f} | "
                    f"{pl['median']:.3f} | {m['skill']:.3f} | {pl['skill_mean']:.3f} / "
                    f"{pl['skill_median']:.3f} | {m['network']['pct_ee_lt_3mm']:.1f} | "
                    f"{m['training_seconds']:.0f} |")
        text = (header("The population basis, regularised one knob at a time").rstrip()
                + "\n\n" + __doc__.split("\n\n")[1].replace("\n", " ") + "\n\n"
                + "| variant | config overrides | MEE mm | median liver MEE mm | skill | "
                "skill mean / median over livers | % EE < 3 mm | training s |\n"
                + "|---|---|---|---|---|---|---|---|\n" + "\n".join(rows) + "\n")
        Path(a.md).write_text(text)
    print(f"report written to {a.md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
