"""A dataset generated in chunks under a wall-time budget, from any interpreter.

``generate_chunks`` runs ``mpirun -n NP SOLVER_PYTHON -m fem_sim generate SCENE --only 0..k``
for growing k until the dataset holds ``n`` simulations or the budget is spent; each run checks
the shards already there (it skips the valid ones and runs again those of another mesh or fixed
region of their liver), and a dataset already complete is checked once. The wall seconds
accumulate in ``DATA/../generation.json`` so that a study run again (or in another session)
goes on where it stopped. It imports no solver: the trainer's environment drives the solver's
this way.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from data_spec.views import shard_count

ROOT = Path(__file__).resolve().parents[2]


def liver_truth(directory: str | Path, scene_text: str, n: int, *, ranks: int = 2,
                solver_python: str | Path | None = None, chunk: int | None = None,
                stale: tuple = (), generate: bool = True) -> Path:
    """The FE truth of a liver a model never saw, in ``directory`` (resumable): the scene
    ``scene_text`` (``surrogate truth-scene``'s: the model's boundary condition) kept as
    ``directory/scene.toml``, its first ``n`` simulations in ``directory/data``. A directory
    holding the truth of another scene (another placement, another model) is emptied first:
    its data, its generation record and the files ``stale`` names. ``generate`` False: only
    the scene (what is there is kept). Returns the data directory.
    """
    import shutil

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    scene = d / "scene.toml"
    if not scene.exists() or scene.read_text() != scene_text:
        shutil.rmtree(d / "data", ignore_errors=True)
        for name in ("generation.json", *stale):
            (d / name).unlink(missing_ok=True)
        scene.write_text(scene_text)
    if generate:
        generate_chunks(scene, d / "data", n, ranks=ranks, solver_python=solver_python,
                        chunk=chunk or n)
    return d / "data"


def meshed_liver(liver: str | Path, scene: str | Path,
                 solver_python: str | Path | None = None) -> Path:
    """The liver file meshed as the population of ``scene`` meshes its livers (``liverfem-sim
    mesh --scene`` in the solver's environment: what ``surrogate.evaluate.place`` registers a
    model's template on, as make liver does), made once and kept under runs/meshes/ by file
    content and mesh size.
    """
    import hashlib

    from data_spec import load_scene

    size = float(load_scene(scene)["geometry"]["mesh_size"])
    key = hashlib.sha256(Path(liver).read_bytes() + repr(size).encode()).hexdigest()[:12]
    out = ROOT / "runs" / "meshes" / f"{Path(liver).stem}-{key}.h5"
    if not out.exists():
        subprocess.run([str(solver_python or ROOT / ".venv-solver" / "bin" / "python"), "-m",
                        "fem_sim", "mesh", str(liver), "--scene", str(scene), "--out",
                        str(out), "--no-picture"], check=True, cwd=ROOT,
                       stdout=subprocess.DEVNULL)
    return out


def mpirun_env(oversubscribe: bool = True, **extra: str) -> dict:
    """The environment of an ``mpirun`` child: this process's, one BLAS and OpenMP thread
    per rank (the ranks take the cores), Open MPI allowed to run as root (a container's
    user), and with ``oversubscribe`` more ranks than cores allowed (a test on one core);
    ``extra`` variables on top.
    """
    return {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
            **({"OMPI_MCA_rmaps_base_oversubscribe": "1"} if oversubscribe else {}),
            "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", **extra}


def generate_chunks(scene: str | Path, data: str | Path, n: int, *, ranks: int = 2,
                    solver_python: str | Path | None = None, chunk: int = 100,
                    budget_s: float = float("inf")) -> dict:
    """Shards 0..n-1 of ``scene`` into ``data`` in chunks of ``chunk``; stops early once
    ``budget_s`` of generation wall time is spent (over every call on this dataset).
    Returns ``{"seconds": wall seconds so far, "sims": shards there}``.
    """
    scene, data = Path(scene), Path(data)
    solver_python = solver_python or ROOT / ".venv-solver" / "bin" / "python"
    state_path = data.parent / "generation.json"
    state = json.loads(state_path.read_text()) if state_path.exists() else {"seconds": 0.0}
    have = shard_count(data)
    checked = have == 0  # each run checks the shards before the new ones (--only 0..k)
    env = mpirun_env(oversubscribe=False)

    def run(upto: int) -> None:
        cmd = ["mpirun", "-n", str(ranks), str(solver_python), "-m", "fem_sim", "generate",
               str(scene), "--out", str(data), "--only", f"0..{upto}"]
        t = time.perf_counter()
        subprocess.run(cmd, check=True, cwd=ROOT, env=env)
        state["seconds"] += time.perf_counter() - t
        data.parent.mkdir(parents=True, exist_ok=True)
        state_path.write_text(json.dumps(state))

    while have < n and state["seconds"] < budget_s:
        upto = min(n, have + chunk)
        print(f"[{scene.stem}] generating simulations {have}..{upto} of {n}", file=sys.stderr,
              flush=True)
        run(upto)
        checked = True
        if shard_count(data) <= have:
            raise RuntimeError(f"{data}: generate made no new shard")
        have = shard_count(data)
    if not checked and state["seconds"] < budget_s:
        # shards made by an earlier call may be of other meshes or fixed regions of the
        # livers (a liver file prepared again): generate checks each and runs those again
        print(f"[{scene.stem}] checking the {n} simulations against the scene's livers",
              file=sys.stderr, flush=True)
        run(n)
    state["sims"] = have
    data.parent.mkdir(parents=True, exist_ok=True)
    state_path.write_text(json.dumps(state))
    return state


def linear_bases(data: str | Path, *, ranks: int = 2, order: int = 2,
                 scene: str | Path | None = None, synthetic: int = 0, green: bool = False,
                 solver_python: str | Path | None = None) -> float | None:
    """The small-strain bases of a dataset from any environment (``fem_sim linear`` in the
    solver's): of every liver of the population dataset ``data`` on ``ranks`` ranks (each
    liver's file skipped when whole), or with ``scene``, of the one-liver dataset ``data`` of
    that scene (``data/linear.h5``, one process, with ``synthetic`` drawn loads and with
    ``green`` the Green's function, as make patient and make liver run it; kept when it holds
    the scene's simulations to ``order``, those drawn loads and that Green's function: a file
    of order 2 serves order 1). Returns the wall seconds of ``fem_sim linear`` when it ran,
    None when every file was kept.
    """
    data = Path(data)
    solver_python = str(solver_python or ROOT / ".venv-solver" / "bin" / "python")
    t = time.perf_counter()
    if scene is None:
        cmd = ["mpirun", "-n", str(ranks), solver_python, "-m", "fem_sim", "linear",
               "--population", str(data), "--order", str(order)]
        subprocess.run(cmd, check=True, cwd=ROOT, env=mpirun_env(oversubscribe=False))
        return time.perf_counter() - t
    from data_spec import load_scene
    from data_spec.linear_fields import linear_fields_path, read_dataset_linear

    if linear_fields_path(data).exists():
        try:
            lf, sc = read_dataset_linear(data), load_scene(scene)
        except ValueError:   # another scene's, or not whole: made again
            lf = None
        if lf is not None and lf.scene_hash == sc.hash and lf.order >= order \
                and lf.case_index.size - lf.synthetic.size >= sc.n_simulations \
                and lf.synthetic.size >= synthetic and (lf.green is not None or not green):
            return None
    subprocess.run([solver_python, "-m", "fem_sim", "linear", str(scene), "--out", str(data),
                    "--synthetic", str(synthetic), *(["--green"] if green else []),
                    "--order", str(order)], check=True, cwd=ROOT)
    return time.perf_counter() - t


def rate_figures(wall_s: float, sim_s, ok: int, total: int, ranks: int) -> dict:
    """A generation's rate from a run from scratch of ``len(sim_s)`` simulations on ``ranks``
    ranks in ``wall_s`` s, each simulation's own seconds ``sim_s`` (``ok`` of them
    converged): the rate on the ranks, and a scene of ``total`` simulations' rate with the
    run's preparation (its core-seconds not in a simulation: meshing, registration, the
    population's shape model) counted once.
    """
    sim_s = np.asarray(sim_s, dtype=np.float64)
    prepare = max(wall_s * ranks - sim_s.sum(), 0.0)   # core-seconds
    return {"ranks": ranks, "sims": int(sim_s.size), "ok": int(ok), "wall_s": float(wall_s),
            "sim_s_median": float(np.median(sim_s)), "sim_s_mean": float(sim_s.mean()),
            "prepare_min": prepare / ranks / 60, "scene_sims": int(total),
            "scene_per_hour": 3600 * total * ranks / (prepare + total * sim_s.mean()),
            "sims_per_hour": 3600 * ranks / sim_s.mean()}


def generation_rate(scene: str | Path, directory: str | Path, n: int, ranks: int) -> dict:
    """``fem_sim generate`` of the scene's first ``n`` simulations on ``ranks`` ranks from
    scratch in ``directory`` (a finished run of ``n`` kept, anything else removed first) and
    its :func:`rate_figures` for the whole scene.
    """
    import shutil

    from data_spec import list_shards, load_scene, read_shard

    d = Path(directory)
    done = d / "generation.json"
    if not (done.exists() and json.loads(done.read_text()).get("sims") == n):
        shutil.rmtree(d, ignore_errors=True)
    state = json.loads(done.read_text()) if done.exists() else generate_chunks(
        scene, d / "data", n, ranks=ranks, chunk=n)
    shards = [read_shard(p) for p in list_shards(d / "data")[:n]]
    return rate_figures(state["seconds"], [np.sum(s.stats.wall_time) for s in shards],
                        sum(s.status == "ok" for s in shards), load_scene(scene).n_simulations,
                        ranks)
