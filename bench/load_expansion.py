"""The small-strain base of a patient model against the Ogden FE: docs/load_expansion.md.

    .venv-train/bin/python bench/load_expansion.py [--model RUN] [--livers Amos-005 LiTS-12
        LiTS-16] [--sims 20] [--ks 5 10] [--np 2]

For each liver (default: the design livers of docs/patient_design.md, training livers, so
that no validation liver enters the choice of a patient model's base), ``--sims`` FE
simulations with the population model's boundary condition and scene 4's settings (as
``make patient`` solves them, resumable under bench/results/load_expansion/), then ``fem_sim
linear`` on the same scene with ``--synthetic 600`` (what make patient asks) at order 1 and
at order 2, each timed; and by load fraction the mean Euclidean error (MEE, mm, over the
nodes, mean over the simulations) of the linear response lam u1 and of the second-order
expansion lam u1 + lam^2 u2 against the FE fields, beside the FE fields' own mean
displacement. The errors' slopes in lam at the first fractions (2 and 3 in theory) are the
check that the expansion is the FE's own; a picture: docs/load_expansion.png. Then the patient
model through :func:`surrogate.patient.held_out_errors` with either base (order 1: the same
simulations with a file of order 1 beside them), adapted on the first K simulations and
measured on the last ``--sims`` - max(K) ones: the base alone, corrected, and the distilled
patient model.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

from data_spec.linear_fields import linear_fields_path
from fem_sim.batch.chunked import liver_truth
from liverviz.report import ROOT, write_report

SCENE = ROOT / "data_spec" / "scenes" / "scene4_livers.toml"
LIVERS = ROOT.parent / "shared" / "data" / "livers" / "real"
RESULTS = ROOT / "bench" / "results" / "load_expansion"
MODEL = ROOT / "bench" / "results" / "scene4_real" / "run_population_basis"
DESIGN_LIVERS = ["Amos-005", "LiTS-12", "LiTS-16"]
SYNTHETIC = 600   # make patient's drawn loads


def truth(model: Path, liver: Path, n: int, ranks: int) -> Path:
    """The liver's ``n`` FE simulations with the model's boundary condition (resumable)."""
    from surrogate.evaluate import truth_scene
    from surrogate.predictor import load_predictor

    return liver_truth(RESULTS / liver.stem,
                       truth_scene(load_predictor(model / "model"), SCENE, liver, n, None), n,
                       ranks=ranks, stale=("linear.json", "patient.json"))


# the variants compared: (order, Green's function) by key; "2" is the truth's own directory
VARIANTS = {"1": (1, False), "2": (2, False), "1g": (1, True), "2g": (2, True)}
LABELS = {"1": "order 1", "2": "order 2", "1g": "order 1, exact linear part",
          "2g": "order 2, exact linear part"}


def order_data(data: Path, key: str) -> Path:
    """The truth's directory with the small-strain file of variant ``key``: ``data`` itself
    for "2", a copy of its shards beside it for the others.
    """
    if key == "2":
        return data
    return data.parent / ("data_order1" if key == "1" else f"data_{key}")


def expansion(data: Path) -> dict:
    """``fem_sim linear`` of each variant (the others into copies of the truth), wall
    seconds each, once per truth (kept in linear.json; a missing file is made again, its
    seconds kept).
    """
    record = data.parent / "linear.json"
    seconds = json.loads(record.read_text()) if record.exists() else {}
    for key, (order, green) in VARIANTS.items():
        out = order_data(data, key)
        if key in seconds and linear_fields_path(out).exists():
            continue
        if out != data:
            shutil.rmtree(out, ignore_errors=True)
            shutil.copytree(data, out, ignore=shutil.ignore_patterns("linear.h5"))
        t = time.perf_counter()
        subprocess.run([str(ROOT / ".venv-solver" / "bin" / "python"), "-m", "fem_sim",
                        "linear", str(data.parent / "scene.toml"), "--out", str(out),
                        "--synthetic", str(SYNTHETIC), "--order", str(order),
                        *(["--green"] if green else [])], cwd=ROOT, check=True,
                       stdout=subprocess.DEVNULL)
        seconds.setdefault(key, time.perf_counter() - t)
    record.write_text(json.dumps(seconds))
    return seconds


def patient_errors(model: Path, liver: Path, data: Path, ks, n: int) -> dict:
    """{"variant/K": held_out_errors} on the last n - max(ks) simulations (kept in
    patient.json; tune off: the population network is not what is compared).
    """
    from surrogate.data import load_dataset
    from surrogate.evaluate import place
    from surrogate.patient import held_out_errors
    from surrogate.predictor import load_predictor

    path = data.parent / "patient.json"
    done = json.loads(path.read_text()) if path.exists() else {}
    pred = load_predictor(model / "model")
    placement = None
    for variant in VARIANTS:
        ds = load_dataset(order_data(data, variant))
        sims = np.unique(ds.sample_sim)
        for k in ks:
            key = f"{variant}/{k}"
            if key in done:
                continue
            if placement is None:
                placement, _ = place(pred, liver, None)
            done[key] = held_out_errors(pred, placement, ds, sims[:k], sims[max(ks):n],
                                        run=data.parent / f"run_{variant}_{k}", tune=False,
                                        log_fn=lambda m: None)
            path.write_text(json.dumps(done, indent=1, default=float))
            print(f"[{liver.stem}] {LABELS[variant]} K={k}: {done[key]}", flush=True)
    return done


def errors(data: Path) -> dict:
    """By load fraction: the FE's mean displacement and the MEE (mm), mean over the
    simulations, of the linear response, the plain series lam u1 + lam^2 u2 and the
    patient model's base (:class:`surrogate.linear_base.LinearBase`: the second term damped,
    and gated where the series is no guide); the worst simulation's at
    fraction 1.
    """
    from surrogate.data import load_dataset
    from surrogate.linear_base import R_MAX, LinearBase
    from surrogate.patient import sample_fields, sims_samples

    ds = load_dataset(data)
    lb = LinearBase(ds)
    sims = np.unique(ds.sample_sim)
    rows = []
    for s in sims:
        smp = sims_samples(ds, [s])
        d = sample_fields(ds, smp)
        lam = np.asarray(ds.sample_fraction[smp], np.float64)
        one = lb.terms(lb.lf.rows(ds.sample_sim[smp]), lam)[0]
        r = lb.lf.rows([s])[0]
        u2 = lb.lf.second_order[r][lb.columns].astype(np.float64)
        rows.append([np.linalg.norm(d, axis=2).mean(axis=1),
                     np.linalg.norm(d - one, axis=2).mean(axis=1),
                     np.linalg.norm(d - one - lam[:, None, None] ** 2 * u2, axis=2).mean(1),
                     np.linalg.norm(d - lb.samples(ds, smp), axis=2).mean(axis=1)])
    a = np.array(rows)   # (sims, 4, fractions)
    names = ("fe", "order1", "order2", "base")
    return {"fractions": np.unique(np.round(ds.sample_fraction, 9)).tolist(),
            "sims": int(sims.size), **{n: a[:, i].mean(0).tolist() for i, n in enumerate(names)},
            "worst": {n: float(a[:, i, -1].max()) for i, n in enumerate(names)},
            "gated": int(np.sum(lb.ratio[lb.lf.rows(sims)] >= R_MAX)),
            "nodes": int(lb.columns.size), "loads": int(lb.lf.case_index.size)}


def slope(lam, err, i: int = 0) -> float:
    """The error's order in lam between the first two fractions."""
    return float(np.log(err[i + 1] / err[i]) / np.log(lam[i + 1] / lam[i]))


def picture(found: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(found), figsize=(4.2 * len(found), 3.6), squeeze=False)
    for ax, (name, e) in zip(axes[0], found.items()):
        lam = np.array(e["fractions"])
        ax.loglog(lam, e["fe"], "k-", label="FE mean displacement")
        ax.loglog(lam, e["order1"], "o-", label="linear (order 1)")
        ax.loglog(lam, e["order2"], "s-", label="series to order 2")
        ax.loglog(lam, e["base"], "^-", label="order-2 base, damped and gated")
        ax.loglog(lam, e["order1"][0] * (lam / lam[0]) ** 2, ":", c="C0", lw=0.8, label="lam^2")
        ax.loglog(lam, e["order2"][0] * (lam / lam[0]) ** 3, ":", c="C1", lw=0.8, label="lam^3")
        ax.set(title=name, xlabel="load fraction", ylabel="mm (mean over nodes and sims)")
        ax.grid(True, which="both", lw=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def patient_lines(patient: dict, a) -> list[str]:
    """The patient model's table: each base by K, held-out MEE (mm)."""
    held = a.sims - max(a.ks)
    lines = ["", f"The patient model with either base (`surrogate.patient.held_out_errors`, "
             f"no fine-tuning), adapted on the first K simulations, MEE (mm) on the last "
             f"{held} (mean over their nodes and load steps); corrected: the kernel "
             "correction on top (dropped where its cross-validation finds no gain); patient "
             "model: distilled and exported as `make patient` does it (with the exact "
             "linear part, `fem_sim linear --green`: the student learns what the teacher "
             "holds beyond the liver's small-strain Green's function, which the exported "
             "model adds back at run time); scratch: the reduced basis trained on the K "
             "alone.", "",
             "| liver | K | base | base alone | corrected | patient model | scratch |",
             "|---|---:|---|---:|---:|---:|---:|"]
    for name, by in patient.items():
        for k in a.ks:
            for v in VARIANTS:
                p = by[f"{v}/{k}"]
                lines.append(f"| {name} | {k} | {LABELS[v]} | {p['linear']:.3f} | "
                             f"{p['linear_corrected']:.3f} | {p['patient_model']:.3f} | "
                             f"{p['scratch']:.3f} |")
    med = {v: {k: np.median([by[f"{v}/{k}"]["patient_model"] for by in patient.values()])
               for k in a.ks} for v in VARIANTS}
    lines += ["", "Median over the livers, patient model: " + "; ".join(
        f"K = {k}: " + ", ".join(f"{LABELS[v]} {med[v][k]:.3f}" for v in VARIANTS) + " mm"
        for k in a.ks) + "."]
    return lines


def report(found: dict, seconds: dict, patient: dict, a) -> str:
    lines = [
        f"Liver files {', '.join(found)} (training livers: no validation liver enters this "
        f"choice), {a.sims} FE simulations each with scene 4's settings (P2, 16 mm, one 0.4 N "
        f"nodal force, 10 load steps) and the boundary condition of the population model "
        f"`{Path(a.model).relative_to(ROOT) if Path(a.model).is_relative_to(ROOT) else a.model}`"
        f"; `fem_sim linear --synthetic {SYNTHETIC}` on the same scene. MEE (mm) of the "
        "small-strain base against the FE fields, by load fraction, mean over the simulations; "
        "slope: the error's order in the load between the first two fractions (2 for the "
        "linear response, 3 for the second-order expansion if its term is the FE's own).", "",
        "Series: lam u1 + lam^2 u2 as the file gives it; base: the patient model's order-2 "
        "base (`LinearBase.terms`: lam^2 u2 / (1 + lam R), R = |u2| / |u1| "
        "of the response, and the linear response alone where R >= 1).", "",
        "| liver | nodes | fraction | FE mean displacement | linear | series | base | "
        "base / linear |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, e in found.items():
        for i in (0, 1, 4, len(e["fractions"]) - 1):
            lines.append(f"| {name} | {e['nodes']} | {e['fractions'][i]:.1f} | {e['fe'][i]:.3f} "
                         f"| {e['order1'][i]:.4f} | {e['order2'][i]:.4f} | {e['base'][i]:.4f} | "
                         f"{e['base'][i] / e['order1'][i]:.2f} |")
    lines += ["", "| liver | slope linear | slope series | mean over fractions, linear | "
              "series | base | worst simulation at fraction 1, linear | series | base | loads "
              "gated | seconds order 1 | order 2 | order 1 --green | order 2 --green "
              "(make patient) |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, e in found.items():
        s = seconds[name]
        lines.append(f"| {name} | {slope(e['fractions'], e['order1']):.2f} | "
                     f"{slope(e['fractions'], e['order2']):.2f} | {np.mean(e['order1']):.3f} | "
                     f"{np.mean(e['order2']):.3f} | {np.mean(e['base']):.3f} | "
                     f"{e['worst']['order1']:.3f} | {e['worst']['order2']:.3f} | "
                     f"{e['worst']['base']:.3f} | {e['gated']} of {e['sims']} | {s['1']:.0f} | "
                     f"{s['2']:.0f} | {s['1g']:.0f} | {s['2g']:.0f} |")
    lines += ["", f"Seconds: `fem_sim linear` in all ({found[next(iter(found))]['loads']} "
              "loads per liver: the simulations' and the drawn ones; meshing, forms, one float64 "
              "factorisation and the block solves), one process.", "",
              "![errors by load fraction](load_expansion.png)"]
    return "\n".join(lines + patient_lines(patient, a))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=str(MODEL), help="the population model's run (its "
                    "placement gives each liver's boundary condition)")
    ap.add_argument("--livers", nargs="+", default=DESIGN_LIVERS)
    ap.add_argument("--sims", type=int, default=20)
    ap.add_argument("--ks", nargs="+", type=int, default=[5, 10],
                    help="the patient's FE simulations adapted on (the rest held out)")
    ap.add_argument("--np", type=int, default=2, help="MPI ranks of the FE")
    a = ap.parse_args()
    if max(a.ks) >= a.sims:
        ap.error(f"--ks: at most {a.sims - 1} (--sims {a.sims}: the rest are held out)")
    found, seconds, patient = {}, {}, {}
    for name in a.livers:
        liver = LIVERS / f"{name}.obj"
        data = truth(Path(a.model), liver, a.sims, a.np)
        seconds[name] = expansion(data)
        found[name] = errors(data)
        print(f"[{name}] {seconds[name]} {found[name]}", flush=True)
        patient[name] = patient_errors(Path(a.model), liver, data, a.ks, a.sims)
    picture(found, ROOT / "docs" / "load_expansion.png")
    write_report(ROOT / "docs" / "load_expansion.md",
                 "Small-strain base of a patient model: order 1 and 2 against the Ogden FE",
                 report(found, seconds, patient, a),
                 {"errors": found, "seconds": seconds, "patient": patient})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
