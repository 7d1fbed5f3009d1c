"""The unseen liver placed each way predict-liver can place it, into docs/unseen_liver.md.

A liver file comes in a frame of its own; predict-liver maps it into the population's frame
before the non-rigid registration (``--frame``: ``population`` keeps its axes and matches the
centroids, ``LPS`` flips x, ``auto`` finds the best rigid fit, turns and mirror images
included; :mod:`liverreg.rigid`). For each, on the liver no training run uses, the report
gives the registration's numbers (residual, folded template tetrahedra, shape coefficients
outside the population's range) and both scene-4 designs' MEE against two FE truths with the
scene's settings on the liver's own mesh:

* fixed where the placement puts the template's fixed region: the boundary condition the
  model assumes, so the error is the surrogate's (each placement has its own truth);
* fixed at the file's default region (the surface within 25 mm of its most posterior point,
  y largest): one truth for all, so the error also counts where the placement put the
  attachment.

The distance column: the liver's mean surface distance to the population's mean liver once
mapped (farthest-point samples both ways). The free fit (auto) is closest by construction; the
second table asks whether that distance could tell a file's frame, on livers of the population
read in each frame.

The networks are told the shape predict-liver tells them by default, the design's rule
(node-wise: each coefficient clipped to the population's range, ``range``; population basis:
beyond the population's largest Mahalanobis radius or its coefficients' range, the nearest mix
of the population's livers, ``outside``; docs/shape_rule.md); a liver inside the population
is told its own coefficients; the "shape told" column says which.
The "mean shape" columns tell them the population's mean shape (coefficients zero) instead:
how much of the error is the networks' answer to the shape they are told.

The clamp's size: the registration can stretch the template's fixed region on a liver unlike
the phantoms. A third truth (``--frame LPS``) is clamped by a patch of the template's own
size, the template's fixed nodes moved to where the registered ones are centred, the models
still placed as predict-liver places them: how much the clamp's size alone changes the FE
answer, against what the models predict.

The phantoms' response against their clamp: each training liver's mean displacement (its
simulations' mean over nodes and load steps) fitted as a power law of three numbers the
response depends on most, its fixed surface's area, the load's distance to the fixed region
and its volume (:func:`clamp_response`, :func:`power_law`), then asked for the unseen
liver under each clamp: whether those numbers explain how stiff the liver is, or its shape
does beyond them.

Where the template's fixed region lands on the phantoms: each training liver is clamped at
its own groove, while a model placed on a new liver assumes the template's fixed region moved
there by the registration. For every liver of the population, the registered region against
the liver's own (:func:`fixed_region_landing`): how far their nodes lie from each other, and
their areas; the unseen liver's registered region is then set beside the population's.

What that costs, on livers with a groove of their own: the 13 phantoms drawn twice as wide of
docs/shape_rule.md (bench/shape_rule_study.py), beyond the population as the unseen liver is,
each with two FE truths on its own mesh: fixed where predict-liver's placement puts the
template's fixed region (the study's truth, the boundary condition the model assumes) and fixed
at the liver's own groove, as every training liver is (:func:`wide_clamp_cost`). The models
are placed and told the shape as predict-liver does; if they are far nearer the second truth,
they predict the clamp they were trained on, not the one they are placed with.

    .venv-train/bin/python bench/unseen_frames.py    # after make table4 T4="--scenes 4" and
                                                     # bench/shape_rule_study.py

Resumable: a truth whose simulations exist is not generated again.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from report import header  # noqa: E402
from table4 import (  # noqa: E402
    RESULTS,
    SCENES,
    UNSEEN,
    design_label,
    evaluate_unseen,
    place_unseen,
    unseen_truth,
)

BASE = RESULTS / "scene4_livers"
DESIGNS = {"paper_scene4": BASE / "run" / "model",
           "population_basis": BASE / "run_population_basis" / "model"}
FRAMES = ("population", "LPS", "auto")
PHANTOMS = 4  # livers of the population in the frame-distance table


def placement_panel(placement, sm, label: str):
    """The registered template in the liver file's frame, its fixed region marked."""
    from liverviz.pictures import Panel, Surface

    # the camera looks at the fixed region (a panel's load nodes only aim it when u is None)
    return Panel(surface=Surface.from_mesh(placement.to_liver(placement.points),
                                           placement.oriented(sm.surface_triangles),
                                           sm.fixed_nodes),
                 label=label, load_nodes=sm.fixed_nodes)


def file_region_picture(panels: list, file_truth: Path, png: Path) -> Path:
    from data_spec import read_geometry
    from liverviz.pictures import Panel, Surface, render_panels

    g = read_geometry(next((file_truth / "geometry").glob("*.h5")))
    region = g.regions["vena_cava"]
    panels = panels + [Panel(surface=Surface.from_mesh(g.points, g.surface_triangles, region),
                             label="the liver's mesh, the file's default region",
                             load_nodes=region)]
    return render_panels(panels, png, title="Where each placement fixes the unseen liver",
                         cols=2)


def clamp_response(data: Path) -> np.ndarray:
    """(n_livers, 4) for each liver of a dataset, averaged over its simulations that
    converged: mean displacement (mm, over output nodes and load steps), area of the fixed
    surface (mm^2), distance of the load to the nearest fixed node (mm), volume (mL).
    """
    from data_spec.geometry import read_geometry, region_area, signed_volumes
    from data_spec.shards import geometry_path, list_shards, read_shard

    per: dict[str, list] = {}
    geo: dict[str, tuple] = {}
    for path in list_shards(data):
        s = read_shard(path)
        if s.status != "ok":
            continue
        if s.geometry_id not in geo:
            g = read_geometry(geometry_path(data, s.geometry_id))
            geo[s.geometry_id] = (g, np.abs(signed_volumes(g.points, g.cells)).sum() / 1e3)
        g, vol = geo[s.geometry_id]
        F = g.points[s.fixed_nodes]
        dist = np.sqrt(((g.points[s.load_nodes][:, None] - F) ** 2).sum(axis=-1)).min()
        per.setdefault(s.geometry_id, []).append(
            (np.linalg.norm(s.displacement, axis=-1).mean(),
             region_area(g.points, g.surface_triangles, s.fixed_nodes), dist, vol))
    return np.array([np.mean(v, axis=0) for v in per.values()])


def fixed_region_landing(data: Path, sm, fixed_name: str) -> np.ndarray:
    """(n_livers, 4) for each liver of the population in ``data``: the median distance (mm)
    from the registered template's fixed nodes to the liver's own fixed nodes (region
    ``fixed_name``), the same from its own to the registered ones, the registered region's
    area and the liver's own region's area (mm^2).
    """
    from scipy.spatial import cKDTree

    from data_spec.geometry import read_geometry, region_area
    from data_spec.shards import geometry_path
    from surrogate.population import registered_templates

    fx = sm.fixed_nodes
    rows = []
    for gid, P in registered_templates(data).items():
        g = read_geometry(geometry_path(data, gid))
        own = g.regions[fixed_name]
        rows.append((np.median(cKDTree(g.points[own]).query(P[fx])[0]),
                     np.median(cKDTree(P[fx]).query(g.points[own])[0]),
                     sm.fixed_area(P), region_area(g.points, g.surface_triangles, own)))
    return np.array(rows)


def wide_clamp_cost(preds: dict, a, scene_file: Path) -> dict:
    """Per wide phantom of bench/shape_rule_study.py (those whose truth it generated): its
    Mahalanobis radius, each truth's fixed node count and mean displacement (mm), and per
    design the MEE against each truth (mm); the own-groove truths are generated here
    (resumable), the results kept in the study's directory."""
    from shape_rule_study import WIDE, WIDE_SIMS, whitened_radius, wide_livers

    from surrogate.predict_liver import shape_rule

    cache = WIDE / "clamp_cost.json"
    # the results hold for these models told the shape by these rules
    stamp = {n: [(Path(DESIGNS[n]) / "params.npz").stat().st_mtime, shape_rule(pred)]
             for n, pred in preds.items()}
    done = json.loads(cache.read_text()) if cache.exists() else {}
    if done.get("models") != stamp:
        done = {"models": stamp, "livers": {}}
    C = preds["population_basis"].shape_model.population_coefficients
    for liver in wide_livers(a):
        landing = WIDE / liver.stem / "data"
        if liver.stem in done["livers"] or not (landing / "sims").is_dir():
            continue
        own = unseen_truth(scene_file, liver, None, None, a, liver.stem + "_own_groove",
                           root=WIDE, sims=WIDE_SIMS)
        row = {}
        for name, pred in preds.items():
            placement, found = place_unseen(pred, liver, "population")
            row["radius"] = float(whitened_radius(placement.coefficients[None], C)[0])
            for truth, data in (("landing", landing), ("own", own)):
                r = evaluate_unseen(pred, data, BASE / "data", placement, found)
                row[f"{name} {truth}"] = r["network"]["mee"]
                row[f"{truth} fixed nodes"] = r["fixed_nodes"]
                row[f"{truth} mean mm"] = r["truth_mean_mm"]
                row[f"{truth} naive"] = r["naive"]["mee"]
        done["livers"][liver.stem] = row
        cache.write_text(json.dumps(done, indent=1))
        print(f"[clamp] {liver.stem}: " + ", ".join(f"{k} {v:.3f}" for k, v in row.items()),
              flush=True)
    return done["livers"]


def wide_grooves(wide: dict, population_areas: np.ndarray, fixed_name: str) -> str:
    """Why the wide phantoms' own grooves hold fewer nodes: their areas (on their own meshes,
    as ``population_areas``, the population's own grooves) and how the node counts follow."""
    from shape_rule_study import liver_dir

    from data_spec.geometry import read_geometry, region_area

    stems = sorted(wide)
    area = np.array([region_area(g.points, g.surface_triangles, g.regions[fixed_name])
                     for g in (read_geometry(liver_dir("wide") / f"{s}.h5") for s in stems)])
    nodes = np.array([wide[s]["own fixed nodes"] for s in stems])
    return (f"\nThe wide phantoms' own grooves cover {np.median(area):.0f} mm^2 median "
            f"({area.min():.0f} .. {area.max():.0f}) on their meshes, the population's "
            f"{np.median(population_areas):.0f} mm^2 ({population_areas.min():.0f} .. "
            f"{population_areas.max():.0f}); over the {len(stems)} wide phantoms the own "
            "groove's fixed node count follows its area (correlation "
            f"{np.corrcoef(area, nodes)[0, 1]:.2f}).\n")


def power_law(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Least squares of log y = b0 + sum_i b_i log X_i: (b, R^2 in the logs); a prediction at
    x is exp(b0 + b[1:] . log x)."""
    A = np.column_stack([np.ones(len(y)), np.log(X)])
    ly = np.log(y)
    b = np.linalg.lstsq(A, ly, rcond=None)[0]
    return b, float(1.0 - ((ly - A @ b) ** 2).sum() / ((ly - ly.mean()) ** 2).sum())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", nargs="+", choices=FRAMES, default=list(FRAMES))
    ap.add_argument("--np", type=int, default=2, help="MPI ranks for the FE truths")
    ap.add_argument("--chunk", type=int, default=1000)
    ap.add_argument("--solver-python", default=str(ROOT / ".venv-solver" / "bin" / "python"))
    ap.add_argument("--unseen", default=str(UNSEEN))
    ap.add_argument("--md", default=str(ROOT / "docs" / "unseen_liver.md"))
    a = ap.parse_args()
    missing = [str(p) for p in [*DESIGNS.values(), Path(a.unseen)] if not p.exists()]
    if missing:
        print(f"missing: {', '.join(missing)}; run make table4 T4=\"--scenes 4\" first",
              file=sys.stderr)
        return 2
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    from data_spec.shards import geometry_path
    from surrogate.export import load_predictor

    scene_file = ROOT / "data_spec" / "scenes" / SCENES[4]
    liver = Path(a.unseen)
    preds = {name: load_predictor(model) for name, model in DESIGNS.items()}
    sm = preds["paper_scene4"].shape_model
    file_truth = unseen_truth(scene_file, liver, None, sm, a, "unseen_file_region")
    from surrogate.predict_liver import read_liver_surface

    def distances(path: Path) -> dict:
        points, tris = read_liver_surface(path)
        return {f: sm.rigid_fit(points, tris, f).distance
                for f in ("population", "LPS", "RAS", "auto")}

    unseen_dist = distances(liver)
    rows, out, panels, placed = [], {}, [], {}
    for frame in a.frames:
        placement, found = place_unseen(preds["paper_scene4"], liver, frame)
        own = unseen_truth(scene_file, liver, placement, sm, a, f"unseen_{frame}")
        placed[frame] = (placement, found, own)
        # the same placement told the population's mean shape (coefficients 0): how much of
        # the error is the networks' answer to this liver's shape coefficients
        mean_shape = dataclasses.replace(placement, coefficients=0.0 * placement.coefficients)
        panels.append(placement_panel(placement, sm, f"--frame {frame}: {placement.frame}, "
                                      f"{placement.inverted} tetrahedra folded"))
        res = {name: {truth: evaluate_unseen(pred, data, BASE / "data", pl, found)
                      for truth, data, pl in (("own", own, placement),
                                              ("file", file_truth, placement),
                                              ("own_mean_shape", own, mean_shape))}
               for name, pred in preds.items()}
        out[frame] = res
        first = res["paper_scene4"]["own"]
        cells = first["template_cells"]
        mee = {(n, t): res[n][t]["network"]["mee"] for n in DESIGNS
               for t in ("own", "file", "own_mean_shape")}
        rows.append(
            f"| `{frame}` | {placement.frame} | {unseen_dist[frame]:.2f} | "
            f"{first['residual_mm']:.2f} | "
            f"{first['inverted']} ({100 * first['inverted'] / cells:.1f} %) | "
            f"{first['coefficients_out']} of {first['coefficients']} | "
            + " / ".join(res[n]["own"]["shape_rule"] for n in DESIGNS) + " | "
            f"{first['fixed_nodes']} | {mee['paper_scene4', 'own']:.2f} | "
            f"{mee['population_basis', 'own']:.2f} | {first['naive']['mee']:.2f} | "
            f"{mee['paper_scene4', 'own_mean_shape']:.2f} | "
            f"{mee['population_basis', 'own_mean_shape']:.2f} | "
            f"{mee['paper_scene4', 'file']:.2f} | {mee['population_basis', 'file']:.2f} | "
            f"{res['paper_scene4']['file']['naive']['mee']:.2f} |")
        (RESULTS / "unseen_frames.json").write_text(json.dumps(out, indent=1))
    pop_inv = int(sm.population_inverted.max(initial=0))
    findings = []
    for frame, res in out.items():
        nv = res["paper_scene4"]["own"]["naive"]["mee"]
        line = []
        for n in DESIGNS:
            own, mean = (res[n][t]["network"]["mee"] for t in ("own", "own_mean_shape"))
            line.append(f"{design_label(n)} {own:.2f} mm ({'better' if own < nv else 'worse'} "
                        f"than naive), {mean:.2f} mm told the mean shape")
        findings.append(f"- `{frame}`: naive {nv:.2f} mm; " + "; ".join(line) + ".")
    text = (header("The unseen liver, placed each way").rstrip() + "\n\n"
            + "\n\n".join(__doc__.split("\n\n")[1:5]) + "\n\n"
            + f"Liver `{liver.name}`; the models of `make table4` scene 4 ("
            + ", ".join(design_label(n) for n in DESIGNS) + "), their population of "
            f"{sm.residuals.size} livers registered with residual "
            f"{np.median(sm.residuals):.2f} mm median ({sm.residuals.max():.2f} at worst) and "
            f"at most {pop_inv} of {sm.template_cells.shape[0]} template tetrahedra folded. "
            "MEE in mm over all nodes and load steps of the truth's simulations; naive: the "
            "population's mean displacement.\n\n"
            "| --frame | placed as | distance to the mean liver mm | residual mm | folded "
            "tetrahedra | coefficients out of "
            "range | shape told (node-wise / population basis) | truth's fixed nodes "
            "| MEE node-wise | MEE population basis | naive "
            "| MEE node-wise, mean shape | MEE population basis, mean shape "
            "| MEE node-wise, file's region | MEE population basis, file's region | naive, "
            "file's region |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
            + "\n".join(rows) + "\n\nAgainst the truth fixed where the placement puts the "
            "template's fixed region:\n\n" + "\n".join(findings) + "\n")
    if "LPS" in out:  # the clamp's size, in predict-liver's default placement
        placement, found, own = placed["LPS"]
        fx = sm.fixed_nodes
        tp = sm.template_points[fx]
        compact = tp - tp.mean(axis=0) + placement.points[fx].mean(axis=0)
        data = unseen_truth(scene_file, liver, placement, sm, a, "unseen_LPS_compact",
                            fixed=placement.to_liver(compact))
        truths = {"where the placement puts the template's fixed region":  # evaluated above
                  ({n: out["LPS"][n]["own"] for n in DESIGNS}, placement.points[fx], own),
                  "a patch of the template's size, centred there":
                  ({n: evaluate_unseen(p, data, BASE / "data", placement, found)
                    for n, p in preds.items()}, compact, data)}
        crow = []
        for label, (res, pts, _) in truths.items():
            first = res["paper_scene4"]
            crow.append(f"| {label} | {first['fixed_nodes']} | "
                        + " x ".join(f"{v:.0f}" for v in np.ptp(pts, axis=0)) + " | "
                        f"{first['truth_mean_mm']:.2f} | " + " | ".join(
                            f"{res[n]['predicted_mean_mm']:.2f} / {res[n]['network']['mee']:.2f}"
                            f" / {res[n]['best_scale']:.2f}" for n in DESIGNS) + " |")
            out.setdefault("clamp", {})[label] = res
        (RESULTS / "unseen_frames.json").write_text(json.dumps(out, indent=1))
        why = next(t for t in __doc__.split("\n\n") if t.startswith("The clamp's size"))
        text += ("\n" + why + "\n\nThe clamp's size (`--frame LPS`; the models placed the "
                 "same way both times): mean displacement of the FE truth, and for each "
                 "design its mean predicted displacement / MEE / the one scale that fits "
                 "its prediction best (mm, mm, factor):\n\n"
                 "| truth clamped at | fixed nodes | fixed region extent x / y / z mm | FE "
                 "mean displacement mm | " + " | ".join(design_label(n) for n in DESIGNS)
                 + " |\n|---|---|---|---|---|---|\n" + "\n".join(crow) + "\n")
        pop = clamp_response(BASE / "data")
        b, r2 = power_law(pop[:, 1:], pop[:, 0])
        frow = []
        for label, (res, _, d) in truths.items():
            u = clamp_response(d)[0]
            fit = float(np.exp(b[0] + b[1:] @ np.log(u[1:])))
            frow.append(f"| {label} | {u[1]:.0f} | {u[2]:.1f} | {u[3]:.0f} | {u[0]:.2f} | "
                        f"{fit:.2f} ({fit / u[0]:.2f}x) | " + " | ".join(
                            f"{res[n]['predicted_mean_mm'] / res[n]['truth_mean_mm']:.2f}x"
                            for n in DESIGNS) + " |")
        out["clamp_fit"] = {"exponents": b.tolist(), "r2": r2, "livers": len(pop)}
        (RESULTS / "unseen_frames.json").write_text(json.dumps(out, indent=1))
        why = next(t for t in __doc__.split("\n\n") if t.startswith("The phantoms' response"))
        text += ("\n" + why + "\n\nOver the population's " + f"{len(pop)} livers (fixed area "
                 + " .. ".join(f"{v:.0f}" for v in np.percentile(pop[:, 1], [0, 100]))
                 + " mm^2, mean displacement " + " .. ".join(
                     f"{v:.1f}" for v in np.percentile(pop[:, 0], [0, 100]))
                 + f" mm): mean displacement = {np.exp(b[0]):.3g} x area^{b[1]:.2f} x "
                 f"distance^{b[2]:.2f} x volume^{b[3]:.2f}, R^2 {r2:.2f} in the logs. The "
                 "unseen liver (`--frame LPS`), its FE mean displacement, the fit's and the "
                 "networks' (each as a multiple of the FE's):\n\n"
                 "| truth clamped at | fixed area mm^2 | load distance mm | volume mL | FE mean "
                 "displacement mm | the phantoms' fit mm | " + " | ".join(
                     design_label(n) for n in DESIGNS) + " |\n|---|---|---|---|---|---|---|---|\n"
                 + "\n".join(frow) + "\n")
    from data_spec.scene import load_scene

    land = fixed_region_landing(BASE / "data", sm, load_scene(scene_file)["fixed"]["name"])
    out["fixed_region_landing"] = land.tolist()
    (RESULTS / "unseen_frames.json").write_text(json.dumps(out, indent=1))
    why = next(t for t in __doc__.split("\n\n") if t.startswith("Where the template's fixed"))
    q = lambda v: " / ".join(f"{x:.1f}" for x in np.percentile(v, [50, 90, 100]))  # noqa: E731
    rng = lambda v: " .. ".join(f"{x:.0f}" for x in np.percentile(v, [0, 100]))  # noqa: E731
    text += ("\n" + why + f"\n\nOver the population's {len(land)} livers (median / p90 / "
             "largest over the livers):\n\n"
             "| | median / p90 / max |\n|---|---|\n"
             f"| registered fixed nodes to the liver's own fixed nodes, median mm | "
             f"{q(land[:, 0])} |\n"
             f"| the liver's own fixed nodes to the registered ones, median mm | "
             f"{q(land[:, 1])} |\n"
             f"| registered region's area / the liver's own | {q(land[:, 2] / land[:, 3])} |\n"
             f"\nFixed areas: the livers' own regions {rng(land[:, 3])} mm^2 (the phantoms' "
             f"grooves, on their meshes), the template's region registered onto them "
             f"{rng(land[:, 2])} mm^2 (on the registered template), the template's own "
             f"{sm.fixed_area(sm.template_points):.0f} mm^2; the template's region registered "
             "onto the unseen liver " + ", ".join(
                 f"{sm.fixed_area(placed[f][0].points):.0f} mm^2 (`--frame {f}`)"
                 for f in placed) + ". (The clamp table's areas are those of the fixed nodes "
             "on the liver's own mesh, as the phantoms' own.)\n")
    wide = wide_clamp_cost(preds, a, scene_file)
    if wide:
        out["wide_clamp_cost"] = wide
        (RESULTS / "unseen_frames.json").write_text(json.dumps(out, indent=1))
        why = next(t for t in __doc__.split("\n\n") if t.startswith("What that costs"))
        cols = [("radius", "{:.1f}"), ("landing fixed nodes", "{:.0f}"),
                ("own fixed nodes", "{:.0f}"), ("landing mean mm", "{:.2f}"),
                ("own mean mm", "{:.2f}")] + [(f"{n} {t}", "{:.3f}") for n in DESIGNS
                                             for t in ("landing", "own")]
        wrow = [f"| `{k}` | " + " | ".join(f.format(r[c]) for c, f in cols) + " |"
                for k, r in sorted(wide.items())]
        wrow.append("| mean | " + " | ".join(
            f.format(np.mean([r[c] for r in wide.values()])) for c, f in cols) + " |")
        text += ("\n" + " ".join(why.split("\n")) + "\n\n| liver | radius | fixed nodes, "
                 "template's region | fixed nodes, own groove | FE mean displacement mm, "
                 "template's region | the same, own groove | " + " | ".join(
                     f"{design_label(n)} MEE mm against the truth fixed at the {t}"
                     for n in DESIGNS for t in ("template's region", "own groove"))
                 + " |\n|---|" + "---|" * len(cols) + "\n" + "\n".join(wrow) + "\n")
        text += wide_grooves(wide, land[:, 3], load_scene(scene_file)["fixed"]["name"])
    phantoms = [geometry_path(BASE / "data", g) for g in sorted(
        np.load(BASE / "data" / "geometry" / "population.npz")["geometry_ids"].tolist())[:PHANTOMS]]
    prow = []
    for name, path in [(f"`{liver.name}` (its frame: LPS)", liver)] + [
            (f"phantom `{p.stem}` (its frame: population)", p) for p in phantoms]:
        dist = unseen_dist if path == liver else distances(path)
        prow.append(f"| {name} | " + " | ".join(
            f"{dist[f]:.2f} ({100 * (dist[f] / dist['auto'] - 1):+.0f} %)"
            for f in ("population", "LPS", "RAS")) + f" | {dist['auto']:.2f} |")
    png = file_region_picture(panels, file_truth, Path(a.md).with_suffix(".png"))
    text += (f"\n![the registered template in the file's frame]({png.name})\n\nThe "
             "registered template in the file's frame, its fixed region (the truth's) marked, "
             "for each placement; last, the liver's own mesh with the file's default region.\n")
    text += ("\nDistance to the mean liver (mm, and against the free fit) of livers read in "
             "each frame:\n\n| liver | population | LPS | RAS | auto |\n|---|---|---|---|---|\n"
             + "\n".join(prow) + "\n")
    Path(a.md).write_text(text)
    print(f"report written to {a.md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
