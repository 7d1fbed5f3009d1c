"""Latency of an exported model: what a call costs through the real ``load_predictor`` path.

``at_scale`` re-exports a trained model's network onto a liver-sized cloud of nodes (its
design's runtime says how: ``on_nodes``), since the cost of one call depends on the design,
the network and the node count, not on the values of the weights or the modes. ``latency``
times calls; ``timed`` gives the figures a report quotes; ``timed_placed`` times a population
model placed on a liver it never saw, at a user's mesh of it; ``grasp_latency`` a grasp over
a Green's function of a given size (data_spec.green_grasp); ``timed_steps`` a command of
several steps (``make liver``) as its user waits for it.
"""

from __future__ import annotations

import tempfile
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np


def _params(model_dir: Path) -> dict:
    from flax import traverse_util

    with np.load(Path(model_dir) / "params.npz", allow_pickle=False) as z:
        return traverse_util.unflatten_dict({k: z[k] for k in z.files}, sep="/")


def typical_inputs(pred) -> tuple[np.ndarray, np.ndarray]:
    """(forces (1, n_loads, 3), extra (1, e)): a force of the largest trained norm per load and
    the middle of the trained material/shape ranges.
    """
    meta = pred.meta
    rng = meta["training_range"]
    f = np.zeros((1, pred.spec.n_loads, 3))
    f[..., 2] = -rng["force_norm_max"]
    lo, hi = np.asarray(rng["extra_min"], float), np.asarray(rng["extra_max"], float)
    return f, ((lo + hi) / 2)[None] if lo.size else np.zeros((1, 0))


def at_scale(model_dir: Path, n_nodes: int, directory: Path, seed: int = 0) -> Path:
    """A copy of the exported model in ``model_dir`` on a synthetic cloud of n_nodes."""
    from surrogate.export import export_model
    from surrogate.predictor import load_predictor

    pred = load_predictor(model_dir)
    meta = pred.meta
    rng = np.random.default_rng(seed)
    base = pred.points if pred.points is not None else rng.uniform(-100, 100, size=(10, 3))
    lo, hi = base.min(axis=0), base.max(axis=0)
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    pts = centre + half * rng.uniform(-1, 1, size=(n_nodes, 3))
    forces, extra = typical_inputs(pred)
    ds = SimpleNamespace(forces=forces, extra=extra, scene_name=meta["scene"], spec=pred.spec,
                         points=[pts], fixed=[np.arange(100)], out_nodes=[np.arange(n_nodes)],
                         triangles=[np.zeros((0, 3), dtype=np.int64)])
    model = pred.runtime.on_nodes(_params(model_dir), n_nodes, rng)
    export_model(directory, model, {**meta["config"], "design": pred.design}, ds)
    return directory


def model_nodes(pred) -> tuple[np.ndarray, np.ndarray]:
    """(points, fixed node ids) a model is timed on: its own liver, or a population model's
    template (it has no mesh of its own).
    """
    if pred.points is None and pred.shape_model is not None:
        return pred.shape_model.template_points, pred.shape_model.fixed_nodes
    return pred.points, pred.fixed


def latency(predict, nodes=None, calls: int = 200,
            new_load_nodes: bool = False) -> tuple[float, float]:
    """(median, 99th percentile) seconds per call of one load case, after warm-up; the same
    load node(s) every call (a manipulator dragging one node), or with ``new_load_nodes`` other
    ones every call (what a call pays for a load where the last one was not: the population
    basis's load context, a node-wise model's load features).
    """
    f, extra = typical_inputs(predict)
    spec = predict.spec
    material = extra[0, :spec.material_dim] if spec.material_dim else None
    geometry = None
    if spec.geometry_dim:
        geometry = (*model_nodes(predict), extra[0, spec.material_dim:])
    # nodes the scene loads where the model knows them (a user grabs the surface; a node it
    # never loaded would time the warning too), else any
    pool = getattr(predict, "loadable", None)
    if pool is None or len(pool) < 2 * spec.n_loads:
        pool = np.arange(7, 7 + (calls + 1) * spec.n_loads)
    pool = np.asarray(pool)
    load_nodes = pool[:spec.n_loads]
    kw = {"nodes": nodes, "material": material, "geometry": geometry}
    for _ in range(5):
        predict(f[0], load_nodes, **kw)
    times = []
    for i in range(calls):
        g = f[0].copy()
        g[:, 2] *= 1.0 - 1e-4 * (i % 100)
        at = (pool[((i + 1) * spec.n_loads + np.arange(spec.n_loads)) % len(pool)]
              if new_load_nodes else load_nodes)
        t = time.perf_counter()
        predict(g, at, **kw)
        times.append(time.perf_counter() - t)
    return float(np.median(times)), float(np.percentile(times, 99))


def timed(model_dir: Path, calls: int, n_nodes: int) -> dict:
    """Median ms per call of the model in ``model_dir``: at its own nodes (``ms_own``, with
    their count ``nodes``), at ``n_nodes`` nodes (``ms_big``), and there with a new load node
    every call (``ms_big_new_load``).
    """
    from surrogate.predictor import load_predictor

    pred = load_predictor(model_dir)
    own = model_nodes(pred)[0].shape[0]
    med_own, _ = latency(pred, None, calls)
    with tempfile.TemporaryDirectory() as tmp:
        big = load_predictor(at_scale(model_dir, n_nodes, Path(tmp) / "big"))
        med_big, _ = latency(big, None, calls)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the cloud's nodes were never loaded: timing only
            med_new, _ = latency(big, None, calls, new_load_nodes=True)
    return {"ms_own": 1e3 * med_own, "ms_big": 1e3 * med_big, "nodes": own,
            "ms_big_new_load": 1e3 * med_new}


def timed_placed(pred, placement, n_nodes: int, calls: int) -> float:
    """Median ms per call of :class:`surrogate.predict_liver.PlacedModel` on the placed liver
    meshed at ``n_nodes`` nodes (points drawn inside the registered template's tetrahedra,
    in the liver's frame: what a user's mesh of the liver gives): the model on the template,
    one sparse interpolation to the nodes, the turn into the liver's frame; the same load
    node every call, the force changing.
    """
    from surrogate.predict_liver import PlacedModel

    sm = pred.shape_model
    rng = np.random.default_rng(0)
    cells = sm.template_cells[rng.integers(0, sm.template_cells.shape[0], n_nodes)]
    w = rng.dirichlet(np.ones(4), n_nodes)
    nodes = placement.to_liver(np.einsum("nk,nkd->nd", w, placement.points[cells]))
    placed = PlacedModel(pred, nodes=nodes, placement=placement)
    at = placed.load_nodes(placement.to_liver(
        placement.points[sm.loadable_nodes[:pred.spec.n_loads]]))
    f = np.tile([[0.0, 0.0, -0.4]], (pred.spec.n_loads, 1))
    times = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for i in range(calls + 5):
            g = f * (1.0 - 1e-4 * (i % 100))
            t = time.perf_counter()
            placed(g, at)
            times.append(time.perf_counter() - t)
    return 1e3 * float(np.median(times[5:]))


def timed_over_green(pred, data, placement, n_nodes: int, calls: int) -> dict:
    """Median ms per call of :class:`surrogate.over_green.OverGreen` (the rest model ``pred``
    placed on the liver of ``data`` over its Green's function): at the mesh's own nodes
    (``ms_own``, their count ``nodes``) and at ``n_nodes`` points drawn inside its
    tetrahedra (``ms_big``: a finer mesh to show); the same load node every call, the force
    changing.
    """
    from surrogate.over_green import OverGreen

    model = OverGreen(pred, data, placement)
    g = model.geometry
    rng = np.random.default_rng(0)
    cells = g.cells[rng.integers(0, g.cells.shape[0], n_nodes)]
    points = np.einsum("nk,nkd->nd", rng.dirichlet(np.ones(4), n_nodes), g.points[cells])
    big = OverGreen(pred, data, placement, nodes=points)
    at = model.green_nodes[:1]
    out = {"nodes": int(model.output_nodes.size)}
    for key, m in (("ms_own", model), ("ms_big", big)):
        times = []
        for i in range(calls + 5):
            f = np.array([[0.0, 0.0, -0.4 * (1.0 - 1e-4 * (i % 100))]])
            t = time.perf_counter()
            m(f, at)
            times.append(time.perf_counter() - t)
        out[key] = 1e3 * float(np.median(times[5:]))
    return out


def grasp_latency(n_out: int = 15400, m: int = 20, calls: int = 200) -> dict:
    """Medians (s) of a grasp's set-up, a whole field and the force alone at ``n_out`` output
    nodes and an ``m``-node patch (a 10 mm patch of a mesh that fine), on a Green's function
    of that shape (its values do not change the work: random, symmetric positive definite
    among the patch).
    """
    from data_spec.green_grasp import GreenGrasp

    def median(f):
        times = []
        for _ in range(calls):
            t = time.perf_counter()
            f()
            times.append(time.perf_counter() - t)
        return float(np.median(times))

    rng = np.random.default_rng(0)
    green = rng.normal(size=(m, 3, n_out, 3))
    a = rng.normal(size=(3 * m, 3 * m))
    green[:, :, :m] = (a @ a.T + 3 * m * np.eye(3 * m)).reshape(m, 3, m, 3)
    nodes, patch = np.arange(n_out), np.arange(m)
    grasp = GreenGrasp(green, patch, nodes, [patch])
    d = np.array([[0.0, 0.0, 20.0]])
    return {"nodes": n_out, "patch_nodes": m,
            "setup_s": median(lambda: GreenGrasp(green, patch, nodes, [patch])),
            "field_s": median(lambda: grasp(d)), "force_s": median(lambda: grasp.force(d))}


def timed_manipulator(data, solver: str, n: int = 5, calls: int = 20) -> dict:
    """The grasp manipulator's base on make liver's directory ``data`` (``make manipulate``,
    ``solver`` the solver environment's python), as a window uses it: seconds to open (the
    solver process started, the liver factorised); then, with the free surface solved in the
    background (:meth:`~surrogate.manipulator.GraspManipulator.prefetch`), milliseconds to
    grasp and answer ``n`` new patches at once (``during_ms``) and ``n`` more once it is done
    (``after_ms``), far from the fixed region and from each other; the background's seconds
    (``prefetch_s``) and a later call's milliseconds (median of ``calls`` a patch).
    """
    from surrogate.manipulator import GraspManipulator

    t = time.perf_counter()
    m = GraspManipulator(data, solver=solver)
    out, later = {"open_s": time.perf_counter() - t, "during_ms": [], "after_ms": []}, []
    try:
        m.prefetch()
        for k, node in enumerate(m.default_nodes(2 * n + 1)[1:]):
            while k == n and m.grown.prefetching:
                time.sleep(0.01)
            t = time.perf_counter()
            m.pick(m.points[node]), m.set_force([0.0, 0.0, 10.0]), m.predict()
            out["during_ms" if k < n else "after_ms"].append((time.perf_counter() - t) * 1e3)
            later += [m.predict().seconds * 1e3 for _ in range(calls)]
    finally:
        m.close()
    return {**out, "prefetch_s": m.grown.prefetch_seconds, "call_ms": float(np.median(later))}
