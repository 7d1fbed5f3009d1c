"""Scene 4's real-liver population into docs/real_population.md (+ .png): how each liver
entered it (rigid fit, registration residual, folded tetrahedra, smallest Jacobian, fixed
area), the PCA's explained variance, and the same registration of the livers it never saw:
the 15 validation livers and the SOFA liver (registered here, never part of the PCA).

    .venv-solver/bin/python bench/real_population.py [--data runs/data/scene4_livers]

and the preparation's wall time on 1 and 2 ranks (``--prep-livers``, ``--prep-repeats``).

Reads the population that ``fem_sim generate data_spec/scenes/scene4_livers.toml`` prepares
(DATA/geometry/livers.json, population.npz); the unseen livers' records are appended to
bench/results/real_population/unseen.jsonl as they come and skipped when there.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from fem_sim.batch.chunked import mpirun_env
from liverviz.ledger import Ledger
from liverviz.report import ROOT, SOFA, header

SCENE = ROOT / "data_spec" / "scenes" / "scene4_livers.toml"
RESULTS = ROOT / "bench" / "results" / "real_population"


def unseen_records(scene) -> list[dict]:
    """The validation livers and the SOFA liver through the population's preparation."""
    from data_spec.livers import validation_files
    from fem_sim.geometry.file_population import (
        Registrar,
        prepare,
        prepared_key,
        region_name,
        template_of,
    )

    g = scene["geometry"]
    path = RESULTS / "unseen.jsonl"
    # kept under what the preparation depends on (file, settings, code): a liver prepared
    # otherwise since is prepared again
    ledger = Ledger(path, key=lambda r: r.get("key"))
    done = ledger.records()
    template, registrars, out = template_of(g), {}, []
    for f, frame in [(f, g["frame"]) for f in validation_files(g)] + [(SOFA, "auto")]:
        key = prepared_key(f, {**g, "frame": frame})
        if key not in done:
            if frame not in registrars:  # the template meshed once, set up once per frame
                registrars[frame] = Registrar(template, region_name(scene), frame)
            _, _, rec = prepare(f, registrars[frame], g["mesh_size"], g.get("fixed_area_min"))
            done[key] = ledger.add({**asdict(rec), "key": key})
        out.append(done[key])
    return out


def preparation_runs(n_livers: int, repeats: int) -> list[dict]:
    """``fem_sim generate --only 0..1`` of the first ``n_livers`` livers of scene 4 into a
    new directory, on 1 and on 2 ranks in turn, ``repeats`` times each: wall seconds (the
    livers meshed and registered, their PCA, one simulation). Kept in preparation.jsonl by
    commit, and skipped when there.
    """
    import subprocess
    import sys
    import tempfile
    import time

    from liverviz.report import commit

    ledger, tag = Ledger(RESULTS / "preparation.jsonl", key=lambda r: (
        r["commit"], r["livers"], r["ranks"], r["repeat"])), commit()
    done = [r for r in ledger if r["commit"] == tag and r["livers"] == n_livers]
    text = SCENE.read_text().replace('"../../../shared/data/livers/real"',
                                     f'"{(ROOT.parent / "shared/data/livers/real").resolve()}"')
    text = text.replace("pca_components = 27", f"pca_components = {n_livers - 1}\n"
                        f"population_size = {n_livers}")
    env = mpirun_env()
    for rep in range(repeats):
        for ranks in (1, 2):
            if any(r["ranks"] == ranks and r["repeat"] == rep for r in done):
                continue
            with tempfile.TemporaryDirectory() as tmp:
                scene = Path(tmp) / "prep.toml"
                scene.write_text(text)
                t0 = time.perf_counter()
                res = subprocess.run(["mpirun", "-n", str(ranks), sys.executable, "-m",
                                      "fem_sim", "generate", str(scene), "--out",
                                      f"{tmp}/d", "--only", "0..1", "--no-progress"],
                                     env=env, capture_output=True, text=True)
                seconds = time.perf_counter() - t0
            if res.returncode:
                raise SystemExit(f"generate failed on {ranks} rank(s):\n{res.stderr[-2000:]}")
            done.append(ledger.add({"commit": tag, "livers": n_livers, "ranks": ranks,
                                    "repeat": rep, "seconds": seconds,
                                    "line": res.stdout.strip().splitlines()[-1]}))
            print(f"[preparation] {ranks} rank(s), run {rep + 1}: {seconds:.0f} s", flush=True)
    return done


def preparation_lines(runs: list[dict]) -> list[str]:
    """The preparation's wall time on 1 and 2 ranks, as report lines."""
    med = {k: float(np.median([r["seconds"] for r in runs if r["ranks"] == k])) for k in (1, 2)}
    n = runs[0]["livers"]
    return ["## Preparing the livers on every rank", "",
            f"`fem_sim generate` meshes and registers a population's liver files on every rank, "
            f"each its share (rank 0 reads them back in order). Wall time of `fem_sim generate "
            f"--only 0..1` on the first {n} livers of scene 4 into a new directory (the livers "
            f"prepared, their PCA, one simulation), median of {len(runs) // 2} runs each, "
            "1 and 2 ranks in turn:", "",
            "| ranks | wall s | ratio to 1 rank |", "|---|---|---|",
            f"| 1 | {med[1]:.0f} | 1.00 |", f"| 2 | {med[2]:.0f} | {med[2] / med[1]:.2f} |", "",
            f"Its batch line on 2 ranks: `{next(r for r in runs if r['ranks'] == 2)['line']}`",
            ""]


def summary_row(label: str, recs: list[dict]) -> str:
    def q(key, fn):
        return fn([r[key] for r in recs])

    return (f"| {label} | {len(recs)} | {q('inverted', sum)} | {q('min_jacobian', min):.3f} | "
            f"{q('min_jacobian', np.median):.3f} | {q('residual', np.median):.2f} | "
            f"{q('residual', max):.2f} | {q('fixed_area', np.median):.0f} | "
            f"{q('fixed_area', min):.0f} | {q('volume_ml', np.median):.0f} | "
            f"{q('seconds', np.median):.1f} |")


def picture(recs: list[dict], unseen: list[dict], png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(11, 3.4))
    for rs, label in ((recs, "population"), (unseen, "never seen")):
        ax[0].hist([r["residual"] for r in rs], bins=20, alpha=0.6, label=label)
        ax[1].hist([r["min_jacobian"] for r in rs], bins=20, alpha=0.6, label=label)
        ax[2].scatter([r["volume_ml"] for r in rs], [r["fixed_area"] for r in rs], s=8,
                      label=label)
    ax[0].set_xlabel("registration residual, mm")
    ax[1].set_xlabel("smallest Jacobian (moved / template cell volume)")
    ax[2].set_xlabel("liver volume, mL")
    ax[2].set_ylabel("fixed area, mm^2")
    for a in ax:
        a.legend(fontsize=7)
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    from data_spec.scene import load_scene

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT / "runs" / "data" / "scene4_livers"))
    ap.add_argument("--md", default=str(ROOT / "docs" / "real_population.md"))
    ap.add_argument("--prep-livers", type=int, default=16,
                    help="livers of the preparation timing (0: no timing)")
    ap.add_argument("--prep-repeats", type=int, default=3)
    a = ap.parse_args(argv)
    scene = load_scene(SCENE)
    recs = json.loads((Path(a.data) / "geometry" / "livers.json").read_text())
    unseen = unseen_records(scene)
    with np.load(Path(a.data) / "geometry" / "population.npz") as z:
        ev = np.cumsum(z["singular_values"] ** 2) / np.sum(z["singular_values"] ** 2)
    png = Path(a.md).with_suffix(".png")
    picture(recs, unseen, png)
    cols = ("| livers | n | folded tetrahedra | smallest Jacobian | median smallest Jacobian | "
            "median residual, mm | worst residual, mm | median fixed area, mm^2 | smallest "
            "fixed area, mm^2 | median volume, mL | median seconds |\n" + "|---" * 11 + "|")
    worst = max(recs + unseen, key=lambda r: r["residual"])
    lines = [header("Scene 4's real-liver population: registration and shape space"),
             "Each liver: repaired and meshed (16 mm), turned into the template phantom's frame "
             "(rigid fit from the scene's frame), the template registered onto it (staged CPD, "
             "then no folded tetrahedron: fem_sim/geometry/file_population.py, liverreg/morph.py)"
             ", fixed where the template's vena-cava region lands (grown to at least half the "
             "template's area). The validation livers and the SOFA liver are registered the "
             "same way here; they are not in the PCA.", "", cols,
             summary_row("population (scene4_livers.toml)", recs),
             summary_row("validation livers and SOFA (never seen)", unseen), "",
             f"- Worst residual: {worst['name']} ({worst['residual']:.2f} mm).",
             f"- Livers whose fixed region had to grow to the bound: "
             f"{sum(r['grown_rings'] > 0 for r in recs)} of {len(recs)}.",
             "- PCA of the population's template-surface displacements, cumulative explained "
             "variance: " + ", ".join(f"{k} components {ev[k - 1]:.3f}" for k in (1, 5, 10, 27)
                                      if k <= ev.size) + ".",
             f"- Rigid fits: {', '.join(sorted({r['frame'].split(' turned')[0] for r in recs}))}"
             f"; median turn from the scene's frame "
             f"{np.median([float(r['frame'].split('by ')[1].split(' ')[0]) for r in recs]):.0f}"
             " degrees (the phantom template is not a real liver's shape).", "",
             f"![registration]({png.name})", ""]
    if a.prep_livers:
        lines += preparation_lines(preparation_runs(a.prep_livers, a.prep_repeats))
    Path(a.md).write_text("\n".join(lines))
    print(f"wrote {a.md}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
