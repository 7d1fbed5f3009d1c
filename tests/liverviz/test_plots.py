"""liverviz.plots: the reports' charts drawn from small hand-made records of the shape each
bench keeps (a chart that no longer matches its bench's records fails here, not in a
two-hour study), and the Pareto front against a hand-picked answer."""

import pytest

from liverviz import plots


def _png(path) -> bool:
    return path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 5000


def test_the_pareto_front_keeps_the_points_no_faster_one_beats():
    pts = [(1.0, 0.5), (2.0, 0.6), (3.0, 0.2), (4.0, 0.2 * (1 - 1e-9)), (5.0, 0.1)]
    # (2, 0.6) is slower and worse than (1, 0.5); (4, ...) gains round-off only
    assert plots.pareto_front(pts) == [(1.0, 0.5), (3.0, 0.2), (5.0, 0.1)]


def test_every_chart_draws_from_its_benchs_records(tmp_path):
    curve = [{"train_sims": n, "skill": s} for n, s in ((50, 0.3), (100, 0.2), (200, 0.15))]
    rows = {1: {"curve": curve, "beyond": [{"overrides": {"folds": 5}, "metrics": {
        "n_simulations": 500, "skill": 0.1}}]}}
    paper = {1: {"sims": 400, "skill": "0.078"}}
    assert _png(plots.learning_curves(rows, paper, 10, tmp_path / "a.png"))
    run = {"id": "r", "spec": {"n_train": 100, "hidden": [50, 50], "node_fraction": 0.5},
           "all": {"mee": 0.2, "ee_p95": 0.5}, "surface": {"mee": 0.3}, "training_seconds": 9}
    lc = [{**run, "spec": {**run["spec"], "n_train": n}} for n in (25, 50, 100)]
    lat = {"r": {"all_float32": 1e-4, "surface_float32": 5e-5}}
    assert _png(plots.surrogate_price_list(lc, [run], [run], lat, {(50, 50): "small"}, 100,
                                           tmp_path / "b.png"))
    pts = {"L": [("mesh P2", "o", "C1", "16", 3.0, 0.01), ("steps", "s", "C2", "", 1.0, 0.05)]}
    assert _png(plots.fem_price_list(pts, "patch load", tmp_path / "c.png"))
    budget = [{"fe": 0.1, "surrogate": 0.2, "total": 0.25, "degree": 2, "h": 8.0,
               "vertices": 900, "sim_hours": 0.5, "train_hours": 0.1}]
    assert _png(plots.error_budget(budget, 5.0, tmp_path / "d.png"))
    shape = {"livers": [{"n": n, "explained_variance": v, "iou_mean": 0.9, "iou_min": 0.8}
                        for n, v in ((1, 0.5), (5, 0.9))]}
    assert _png(plots.shape_model(shape, 0.85, tmp_path / "e.png"))
    held = {"mee_mm": [0.2, 0.4], "peak_mm": [10.0, 40.0]}
    assert _png(plots.error_against_peak([{"liver": "A", "held_out_sims": {"0": held,
                                                                            "40": held}}],
                                         40, 0.5, 30.0, tmp_path / "f.png"))
    m = {"mee_median": 1.0, "mee_worst": 2.0}
    grasp = [{"pull": p, "base": m, "naive": m, "force_error_median": 10.0,
              "force_error_worst": 20.0} for p in (5.0, 40.0)]
    force = [{"force": f, "base": m, "naive": m} for f in (0.4, 4.0)]
    assert _png(plots.surgical_curves(grasp, force, {"median": 0.5, "force": 5.0},
                                      tmp_path / "g.png"))
    modelled = [{**r, "model": {**m, "force_median": 5.0, "force_worst": 9.0}} for r in grasp]
    assert _png(plots.surgical_curves(modelled, [{**r, "model": m} for r in force],
                                      {"median": 0.5, "force": 5.0}, tmp_path / "g2.png"))
    with pytest.raises(KeyError):   # a model row without its force error
        plots.surgical_curves([{**r, "model": m} for r in grasp], force,
                              {"median": 0.5, "force": 5.0}, tmp_path / "g3.png")
    with pytest.raises(KeyError):   # a record without the figure the chart draws
        plots.surgical_curves([{"pull": 5.0}], force, {"median": 0.5, "force": 5.0},
                              tmp_path / "h.png")
