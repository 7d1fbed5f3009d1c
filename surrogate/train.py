"""Training: k-fold cross-validation, metrics, plots and the exported model; files and printing
live here, the loop itself in :mod:`surrogate.engine`, the designs in :mod:`surrogate.designs`.

Cross-validation splits by simulation (by liver when the geometry varies); inside each fold a
fraction of the training simulations is held out for early stopping and the learning-rate
rule, so the reported metrics come from folds the model never saw in any way.

A run resumes: every fit checkpoints after each epoch (``RUN/checkpoints/``) and every finished
fold keeps its predictions, so the same command after a kill continues where it stopped.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from data_spec.atomic import atomic_path, check_writable
from surrogate import engine
from surrogate.data import Dataset, kfold_groups, load_dataset, training_samples
from surrogate.designs import DESIGNS
from surrogate.export import export_model
from surrogate.metrics import displacement_metrics, mee, metrics_table
from surrogate.nodewise import example_index
from surrogate.plots import error_plots


def inner_split(ds: Dataset, train_samples: np.ndarray, cfg: dict, rng):
    """(training, early-stopping) samples: ``inner_val_fraction`` of the simulations (of the
    livers when the geometry varies) of ``train_samples`` held out.
    """
    unit = ds.sample_geo if ds.spec.geometry_dim else ds.sample_sim
    units = np.unique(unit[train_samples])
    n_val = max(1, int(round(cfg["inner_val_fraction"] * units.size))) if units.size > 1 else 0
    val_units = rng.choice(units, size=n_val, replace=False) if n_val else np.array([])
    is_val = np.isin(unit[train_samples], val_units)
    return train_samples[~is_val], train_samples[is_val]


def early_stopping_split(ds: Dataset, train_samples: np.ndarray, cfg: dict, seed: int):
    """(training samples, early-stopping samples, rng) of a fit with this seed: every design's
    fit starts here, so the exported model's unseen simulations are known without training.
    """
    rng = np.random.default_rng(seed)
    tr, va = inner_split(ds, train_samples, cfg, rng)
    return tr, va, rng


def fit_design(ds: Dataset, train_samples: np.ndarray, cfg: dict, seed: int, label: str = "",
               log_fn=print, checkpoint: engine.Checkpoint | None = None) -> tuple:
    """(model, history): the config's design trained on ``train_samples`` by the engine."""
    design = DESIGNS[cfg["design"]]
    design.check(ds)
    tr, va, rng = early_stopping_split(ds, train_samples, cfg, seed)
    problem = design.problem(ds, tr, va, cfg, rng)
    # An ensemble (cfg "ensemble" > 1): the same problem (modes, statistics, held-out
    # simulations) fitted from other initialisations, batch orders and noise, each member
    # checkpointed in a folder of its own; the first member is the single model.
    members = cfg.get("ensemble", 1)
    one = members == 1
    summary = design.summary(problem) if hasattr(design, "summary") else None
    fitted, history = [], []
    for m in range(members):
        who = label if one else f"{label}member {m + 1}/{members} "
        ck = checkpoint if one or checkpoint is None else engine.Checkpoint(
            checkpoint.dir / f"member{m}", checkpoint.identity)
        params, hist = engine.fit(problem, cfg, seed + 7919 * m,
                                  rng if m == 0 else np.random.default_rng([seed, m]),
                                  label=who, log_fn=log_fn,
                                  log_every=getattr(design, "log_every", 1), checkpoint=ck)
        fitted.append(params)
        history += hist if one else [{**h, "member": m} for h in hist]
        if summary is not None:
            log_fn(f"{who}stopped after {len(hist)} epochs" + (f"; {summary}" if one else ""))
    if one:
        return design.model(problem, fitted[0]), history
    if summary is not None:
        log_fn(f"{label}{members} members; {summary}")
    return design.model(problem, stack_members(fitted), members=members), history


def stack_members(params: list):
    """One parameter tree whose arrays carry the members along a new leading axis."""
    import jax

    return jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(x) for x in a]), *params)


def predict_design(ds: Dataset, model, cfg: dict, samples: np.ndarray):
    """Predicted and true displacement (mm) and the sample of each row, for ``samples``."""
    return DESIGNS[cfg["design"]].predict_samples(ds, model, cfg, samples)


def training_mean(ds: Dataset, samples: np.ndarray) -> np.ndarray:
    """(3,) mm: the mean displacement over the examples of ``samples`` (the naive model
    trained on them).
    """
    _, _, rows = example_index(ds, samples)
    return ds.targets[rows].mean(axis=0)


def per_liver(pred: np.ndarray, true: np.ndarray, naive: np.ndarray, geo: np.ndarray) -> dict:
    """Each liver's MEE and skill (``geo``: the liver of each row), as the paper's scene-4 row
    gives them: the median liver's MEE, skill as mean / median over the livers.
    """
    ee = np.linalg.norm(pred - true, axis=1)
    ee_naive = np.linalg.norm(naive - true, axis=1)
    livers = np.unique(geo)
    per = np.array([ee[geo == g].mean() for g in livers])
    skill = per / np.array([ee_naive[geo == g].mean() for g in livers])
    return {"mean": float(np.mean(per)), "median": float(np.median(per)),
            "values": per.tolist(), "skill_mean": float(np.mean(skill)),
            "skill_median": float(np.median(skill))}


def _save_fold(path: Path, pred, true, smp, naive, history) -> None:
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, pred=pred, true=true, smp=smp, naive=naive,
                 history=np.frombuffer(json.dumps(history).encode(), dtype=np.uint8))


def _load_fold(path: Path):
    try:
        with np.load(path, allow_pickle=False) as z:
            return (z["pred"], z["true"], z["smp"], z["naive"],
                    json.loads(z["history"].tobytes().decode()))
    except (OSError, ValueError, KeyError):
        return None


def _load(data_dir, run: Path, cfg: dict, say) -> Dataset:
    """The dataset, checked for the config's design; no empty run directory is left behind a
    dataset that cannot be read.
    """
    created = not run.exists()
    check_writable(run)  # a read-only run directory fails now, not after the training
    try:
        ds = load_dataset(data_dir, stream=cfg.get("stream", "auto"), spill_dir=run)
    except Exception:
        if created:
            shutil.rmtree(run, ignore_errors=True)
        raise
    say(f"dataset {data_dir}: {ds.n_samples} samples ({np.unique(ds.sample_sim).size} "
        f"simulations, {ds.failed_sims} failed), {ds.targets.shape[0]:,} node examples, "
        f"{ds.spec.dim} features: {', '.join(ds.spec.names())}"
        + ("; targets streamed from disk" if isinstance(ds.targets, np.memmap) else ""))
    if ds.missing_sims:
        say(f"warning: {len(ds.missing_sims)} of the scene's simulations have no shard "
            f"(simulation {', '.join(map(str, ds.missing_sims[:10]))}"
            f"{' ...' if len(ds.missing_sims) > 10 else ''}): `python -m data_spec validate "
            f"{data_dir}` says how to make them")
    DESIGNS[cfg["design"]].check(ds, cfg)
    return ds


def _cross_validate(ds: Dataset, cfg: dict, ckpt: Path, identity: str, say) -> dict:
    """Every evaluated fold trained (or read back from its checkpoint) and predicted: the
    held-out predictions, truths, samples and naive fields per fold, the history, the
    training seconds and examples.
    """
    folds = kfold_groups(ds, cfg["folds"], cfg["seed"])[:cfg.get("evaluate_folds") or None]
    cv = {"pred": [], "true": [], "smp": [], "naive": [], "history": {}, "seconds": 0.0,
          "examples": 0.0, "n_folds": len(folds), "trained_on": []}
    for k, held in enumerate(folds):
        done = ckpt / f"fold{k}" / f"result-{identity}.npz"
        saved = _load_fold(done)
        train_samples = training_samples(ds, held, cfg)
        cv["trained_on"].append((np.unique(ds.sample_geo[train_samples]).size,
                                 np.unique(ds.sample_sim[train_samples]).size))
        if saved is not None:
            p, y, s, mean_disp, hist = saved
            hist = [{**h, "earlier": True} for h in hist]  # trained by another process
            say(f"fold {k + 1}/{len(folds)} done before (from {done})")
        else:
            model, hist = fit_design(ds, train_samples, cfg, cfg["seed"] + 1 + k,
                                     f"fold {k + 1}/{len(folds)} ", say,
                                     engine.Checkpoint(ckpt / f"fold{k}", identity))
            p, y, s = predict_design(ds, model, cfg, held)
            mean_disp = training_mean(ds, train_samples)
            _save_fold(done, p, y, s, mean_disp, hist)
        # from the epochs' own records, so a resumed run reports the whole training
        cv["examples"] += sum(h["examples_per_s"] * h["seconds"] for h in hist)
        cv["seconds"] += sum(h["seconds"] for h in hist)
        cv["history"][f"fold{k}"] = hist
        for key, value in (("pred", p), ("true", y), ("smp", s),
                           ("naive", np.broadcast_to(mean_disp, y.shape))):
            cv[key].append(value)
    return cv


def earlier_seconds(history: list[dict]) -> float:
    """The seconds of the epochs another process trained (a resumed run's earlier part)."""
    return sum(h["seconds"] for h in history if h.get("earlier"))


def _result(ds: Dataset, cfg: dict, cv: dict) -> dict:
    """metrics.json's content: the pooled metrics of the held-out folds beside the naive
    model's, each fold's own, and the training's cost.
    """
    pred, true, smp, nv = (np.concatenate(cv[k]) for k in ("pred", "true", "smp", "naive"))
    m_nn, m_naive = displacement_metrics(pred, true), displacement_metrics(nv, true)
    seconds = cv["seconds"]
    result = {"scene": ds.scene_name, "folds": cfg["folds"], "evaluated_folds": cv["n_folds"],
              "network": m_nn, "naive": m_naive, "skill": m_nn["mee"] / m_naive["mee"],
              "n_simulations": int(np.unique(ds.sample_sim).size),
              "n_samples": int(ds.n_samples), "n_examples": int(ds.targets.shape[0]),
              # a fold's training set (its early-stopping share included), mean over folds
              "train_livers": float(np.mean([n for n, _ in cv["trained_on"]])),
              "train_simulations": float(np.mean([n for _, n in cv["trained_on"]])),
              # each evaluated fold's own MEE and skill (the spread of the held-out sets)
              "per_fold": [{"mee": mee(p, y), "skill": mee(p, y) / mee(n, y)}
                           for p, y, n in zip(cv["pred"], cv["true"], cv["naive"])],
              "training_seconds": seconds,
              "training_examples_per_s": cv["examples"] / seconds if seconds else 0.0}
    if ds.spec.geometry_dim or len(ds.geo_ids) > 1:
        result["per_liver_mee"] = per_liver(pred, true, nv, ds.sample_geo[smp])
        result["per_liver_mee"]["geometry_ids"] = [ds.geo_ids[g]
                                                   for g in np.unique(ds.sample_geo[smp])]
    return result


def _final_fit(ds: Dataset, cfg: dict, run: Path, ckpt: Path, identity: str, say) -> list:
    """The exported model, trained on every simulation; its history."""
    every = training_samples(ds, np.zeros(0, int), cfg)
    model, hist = fit_design(ds, every, cfg, cfg["seed"], "final ", say,
                             engine.Checkpoint(ckpt / "final", identity))
    _, held, _ = early_stopping_split(ds, every, cfg, cfg["seed"])
    export_model(run / "model", model, cfg, ds, np.unique(ds.sample_sim[held]))
    say(f"model exported to {run / 'model'}")
    return hist


def train_and_evaluate(data_dir: str | Path, run_dir: str | Path, cfg: dict,
                       log_fn=None, fresh: bool = False) -> dict:
    """k-fold CV + metrics + plots + (optionally) a final model exported to RUN/model.

    Resumes from RUN/checkpoints when they belong to the same configuration and dataset
    (``fresh=True`` discards them); they are removed once the run is complete.
    """
    run = Path(run_dir)
    lines = []

    def say(msg):
        lines.append(msg)
        (log_fn or (lambda m: print(m, file=sys.stderr, flush=True)))(msg)

    t0 = time.perf_counter()
    ds = _load(data_dir, run, cfg, say)
    (run / "config.json").write_text(json.dumps(cfg, indent=1))
    ckpt = run / "checkpoints"
    if fresh:
        shutil.rmtree(ckpt, ignore_errors=True)
    identity = engine.config_hash(cfg, {"data": str(Path(data_dir).resolve()),
                                        "samples": int(ds.n_samples),
                                        "examples": int(ds.targets.shape[0])})
    cv = _cross_validate(ds, cfg, ckpt, identity, say)
    result = _result(ds, cfg, cv)
    table = metrics_table({"network": result["network"],
                           "naive (mean displacement)": result["naive"]})
    how = (f"{cfg['folds']}-fold cross-validation" if cv["n_folds"] == cfg["folds"] else
           f"the first {cv['n_folds']} of {cfg['folds']} folds held out")
    md = (f"# {ds.scene_name}: {how}\n\n{table}\n\n"
          f"skill = MEE_NN / MEE_naive = {result['skill']:.4f} (paper, scene 1: 0.078)\n")
    say("\n" + table + f"\nskill = MEE_NN / MEE_naive = {result['skill']:.4f}")
    error_plots(run, np.concatenate(cv["pred"]), np.concatenate(cv["true"]), result)
    if cfg["final_fit"]:
        cv["history"]["final"] = _final_fit(ds, cfg, run, ckpt, identity, say)
    # this process's wall time and the epochs earlier processes trained (a resumed run)
    result["total_seconds"] = time.perf_counter() - t0 + sum(
        earlier_seconds(h) for h in cv["history"].values())
    (run / "metrics.json").write_text(json.dumps(result, indent=1))
    (run / "metrics.md").write_text(md)
    (run / "history.json").write_text(json.dumps(cv["history"], indent=1))
    (run / "log.txt").write_text("\n".join(lines) + "\n")
    if isinstance(ds.targets, np.memmap):
        Path(ds.targets.filename).unlink(missing_ok=True)  # a cache, not a result
    shutil.rmtree(ckpt, ignore_errors=True)  # the run is complete
    return result


def train_or_reuse(data_dir: str | Path, run_dir: str | Path, name: str,
                   overrides: dict | None = None) -> dict:
    """The metrics of config ``name`` (with ``overrides``) trained on a dataset: a finished run
    in ``run_dir`` is reused when it holds the same config and was trained on the simulations
    the dataset now holds (RUN/trained_on.json: their count and the dataset's fingerprint, a
    run recorded without one by its count alone), else it is trained (again). What a study
    that grows its dataset, or is run again, needs.
    """
    from data_spec.views import dataset_fingerprint, shard_count
    from surrogate.config import BASE, get_config

    run = Path(run_dir)
    metrics, seen = run / "metrics.json", run / "trained_on.json"
    cfg = get_config(name, **(overrides or {}))
    now = {"shards": shard_count(data_dir), "fingerprint": dataset_fingerprint(data_dir)}
    if metrics.exists() and (run / "config.json").exists():
        # keys added to the trainer since that run take the base default
        same = {**BASE, **json.loads((run / "config.json").read_text())} == cfg
        m = json.loads(metrics.read_text())
        was = json.loads(seen.read_text()) if seen.exists() else \
            {"shards": m["n_simulations"]}
        if same and all(was[k] == now[k] for k in was if k in now):
            return m
        other = was.get("fingerprint", now["fingerprint"]) != now["fingerprint"]
        print(f"[{run}] trained on {was['shards']} simulations with "
              f"{'the same' if same else 'another'} config; the dataset holds {now['shards']}"
              f"{', other ones' if other else ''}: training again", file=sys.stderr, flush=True)
    train_and_evaluate(data_dir, run, cfg)
    seen.write_text(json.dumps(now))
    return json.loads(metrics.read_text())


def _reuse_timed(label: str, data_dir, run_dir, name: str, overrides: dict) -> dict:
    """:func:`train_or_reuse`, its skill and seconds printed under ``label``."""
    t = time.perf_counter()
    m = train_or_reuse(data_dir, run_dir, name, overrides)
    print(f"[{label}] skill {m['skill']:.3f} ({time.perf_counter() - t:.0f} s)", flush=True)
    return m


def train_all(data_dir: str | Path, runs: dict, jobs: int = 1) -> dict:
    """The metrics of every run of ``runs`` (label: (run_dir, config name, overrides)), trained
    or reused as :func:`train_or_reuse` does, ``jobs`` at a time, each in a spawned process of
    its own (a training takes one core; XLA's thread pool is not fork-safe). In the order
    given: put the slow ones last, so that a study cut short has the most runs.
    """
    args = {label: (label, data_dir, *run) for label, run in runs.items()}
    if jobs <= 1:
        return {label: _reuse_timed(*a) for label, a in args.items()}
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as ex:
        futures = {label: ex.submit(_reuse_timed, *a) for label, a in args.items()}
        return {label: f.result() for label, f in futures.items()}
