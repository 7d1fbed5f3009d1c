"""Scene-driven batch generation under MPI: atomic, resumable shards, dynamic work sharing.

Layout: COMM_WORLD is split into groups of R ranks (``--ranks-per-sim``). Each group solves whole
simulations (domain decomposition inside the group); groups take the next case from a shared
atomic counter (an MPI window on world rank 0), so a slow or failing case never idles the others.

Before any MPI work: world rank 0 validates the scene, builds and checks every geometry, writes
the geometry files and decides which shards are missing or corrupt; the verdict is broadcast, so
a bad scene ends every rank with its message instead of hanging. The liver files of a population
are meshed and registered by every rank, each its share, once the scene is checked. The forms
are compiled once on rank 0 before the split (FFCx waits only 10 s for another process
compiling the same form).
"""

from __future__ import annotations

import logging
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from data_spec import (
    Geometry,
    Scene,
    SceneError,
    Shard,
    SolverStats,
    geometry_path,
    load_scene,
    read_geometry,
    shard_path,
    solver_rules,
    write_geometry,
    write_shard,
)
from data_spec.atomic import atomic_path, check_writable, leftover_temporaries
from data_spec.grown import accepted_hashes, record_size, same_but_size
from data_spec.scene import dataset_copy_text
from data_spec.validate import checked_shard
from fem_sim.batch import cases as cs
from fem_sim.batch.lock import DirectoryLock, LockedError
from fem_sim.geometry.quality import mesh_problems
from fem_sim.geometry.source import GeometryError, n_geometries, scene_geometries
from fem_sim.solver.results import WorkCounts

log = logging.getLogger(__name__)


@dataclass
class Plan:
    """What rank 0 decided before work starts (broadcast to every rank)."""

    error: str = ""
    tasks: list[int] | None = None
    skipped: int = 0
    geometry_ids: list[str] | None = None
    prepared: list[int] | None = None  # liver files each rank meshed and registered


def solver_settings(scene: Scene) -> dict:
    """The scene's solver keys that are solver settings (all but the discretisation's)."""
    from data_spec.solver_settings import fields

    return {f.name: scene["solver"][f.name] for f in fields(scene_only=True)}


def parse_range(text: str | None, n: int) -> range:
    """'I..J' -> range(I, J) (J exclusive, either side may be omitted); None -> all."""
    if not text:
        return range(n)
    try:
        lo, hi = text.split("..")
        lo, hi = int(lo) if lo else 0, min(int(hi) if hi else n, n)
    except ValueError:
        raise ValueError(f"--only: expected I..J (e.g. 0..100), got {text!r}") from None
    if lo < 0 or hi <= lo:
        raise ValueError(f"--only {text}: expected 0 <= I < J <= {n} (n_simulations)")
    return range(lo, hi)


def _geometry_file_ok(path: Path, g: Geometry) -> bool:
    if not path.exists():
        return False
    try:
        old = read_geometry(path)
    except Exception as exc:  # truncated or corrupt: it is written again
        log.warning("%s cannot be read (%s); writing it again", path, exc)
        return False
    a, b = old.shape_coefficients, g.shape_coefficients  # a population's may come later
    same = (a is None and b is None) or (a is not None and b is not None and
                                         np.array_equal(a, b))
    # a liver file prepared again may keep its mesh (the same id) and fix other nodes
    regions = old.regions.keys() == g.regions.keys() and all(
        np.array_equal(old.regions[k], g.regions[k]) for k in g.regions)
    return old.content_hash == g.content_hash and same and regions


def _shard_is_done(path: Path, hashes: set[str], retry_failed: bool, geometry_id: str,
                   fixed: np.ndarray, geometry_cache: dict | None = None) -> bool:
    """Whether the shard at ``path`` is a valid simulation of this scene (its scene hash one
    of ``hashes``: :func:`data_spec.grown.accepted_hashes`) on this liver: its mesh
    (``geometry_id``) and its fixed nodes; a shard of another mesh of the liver (a liver
    file prepared again by other code) or of another fixed region is run again.
    ``geometry_cache``: :func:`data_spec.validate.checked_shard`'s (each liver read once).
    """
    if not path.exists():
        return False
    problems, arr, attrs = checked_shard(path, geometry_cache)
    if (problems or attrs["scene_hash"] not in hashes or attrs["geometry_id"] != geometry_id
            or not np.array_equal(arr["/fixed_nodes"], fixed)):
        return False
    return not (retry_failed and attrs["status"] == "failed")


def geometry_of(scene: Scene, index: int, n_geometries: int) -> int:
    """The liver (its index in the scene's geometries) of simulation ``index``."""
    return index % n_geometries if not scene.cases else (
        scene.cases[index].get("geometry_index", 0))


_LOCK: DirectoryLock | None = None  # held by world rank 0 for the whole run


def _check_directory(scene: Scene, out: Path) -> None:
    """Lock ``out`` for this run, clear what an interrupted writer left, refuse a directory
    of another scene's dataset and prove it writable (rank 0).
    """
    global _LOCK
    _LOCK = DirectoryLock(out).acquire()
    for tmp in leftover_temporaries(out):  # we hold the lock: no writer is running
        log.info("removing %s, left by an interrupted writer", tmp)
        tmp.unlink()
    copy = out / "scene.toml"
    if copy.exists() and any((out / "sims").glob("sim_*.h5")):
        try:
            old = load_scene(copy)
        except SceneError:
            old = None
        if old is None or not same_but_size(scene, old):
            raise SceneError(str(out), [f"{out} holds a dataset of another scene "
                                        f"({copy}); use a new --out directory"])
        if old.n_simulations > scene.n_simulations:  # a dataset grows, it never shrinks
            raise SceneError(str(out), [
                f"{out} holds this scene at n_simulations = {old.n_simulations}: "
                f"{scene.n_simulations} would leave shards past its end; keep or raise it, "
                "or use a new --out directory"])
    for d in (out, out / "sims", out / "geometry"):  # fail now, not at the first write
        check_writable(d)


def _scene_livers(scene: Scene, out: Path, progress: bool) -> list[Geometry]:
    """The scene's livers, meshed, read or registered, with a progress bar per stage of a
    population (meshing, registration), opened at its first liver.
    """
    bars = {}
    population = progress and scene["geometry"]["source"] == "population"

    def tick(desc):
        def update(_):
            from tqdm import tqdm

            for other in [d for d in bars if d != desc]:
                bars.pop(other).close()
            if desc not in bars:
                bars[desc] = tqdm(total=n_geometries(scene), unit="liver",
                                  desc=desc, file=sys.stderr)
            bars[desc].update()
        return update if population else None

    try:
        return scene_geometries(scene, cache=out / "geometry" / "population.npz", dataset=out,
                                meshed=tick("livers (meshed or read)"),
                                progress=tick("shape coefficients (CPD)"))
    finally:
        for bar in bars.values():
            bar.close()


def _write_livers(scene: Scene, scene_file: str, livers: list[Geometry],
                  out: Path) -> tuple[list, list]:
    """Every liver checked against the scene (mesh, fixed region, eligible load nodes) and
    written once; their geometry ids and fixed nodes.
    """
    ids, fixed_sets = [], []
    for gi, g in enumerate(livers):
        scene.check_mesh(g.n_nodes)
        fixed = cs.fixed_nodes(scene, g, scene_file)
        bad = mesh_problems(g.points, g.cells, fixed)
        if bad:
            raise GeometryError(f"{scene_file}: geometry {gi} ({g.description}): "
                                + "; ".join(bad))
        if not scene.cases:
            eligible = cs.eligible_load_nodes(scene, g, fixed)
            if eligible.size < scene["loads"]["count"]:
                raise cs.CaseError(f"{scene_file}: geometry {gi} has {eligible.size} "
                                   "eligible load nodes (loads.eligible, "
                                   "min_distance_to_fixed)")
        path = geometry_path(out, g.geometry_id)
        if not _geometry_file_ok(path, g):  # missing, truncated or another mesh: rewrite
            write_geometry(path, g)
        ids.append(g.geometry_id)
        fixed_sets.append(fixed)
    return ids, fixed_sets


def check_run(scene_file: str, out: Path, only: str | None,
              ranks_per_sim: int = 1) -> tuple[Plan, Scene | None]:
    """Rank 0 only, before anything is prepared: the scene, ``--only`` and the solver
    settings checked, ``out`` locked for this run and proved writable.
    """
    def check():
        scene = load_scene(scene_file)
        parse_range(only, scene.n_simulations)  # a bad --only writes nothing
        found = solver_rules.scene_problems(scene["solver"], ranks=ranks_per_sim)
        if found:  # the scene allows it on some rank count, not on this one
            raise SceneError(scene_file, found)
        _check_directory(scene, out)
        return Plan(), scene
    return _guarded(check)


def make_plan(scene: Scene, scene_file: str, out: Path, only: str | None, retry_failed: bool,
              progress: bool = False) -> Plan:
    """Rank 0 only, after :func:`check_run`: every liver built and checked, the scene
    recorded, and the work decided.
    """
    def plan():
        todo = parse_range(only, scene.n_simulations)
        ids, fixed = _write_livers(scene, scene_file, _scene_livers(scene, out, progress),
                                   out)
        # Everything checked: record the scene (a directory without shards takes a new one).
        copy = out / "scene.toml"
        old = load_scene(copy) if copy.exists() else None
        if old is None or old.hash != scene.hash:
            if old is not None and any((out / "sims").glob("sim_*.h5")):
                record_size(out, old.n_simulations)  # its shards stay the scene's
            with atomic_path(copy) as tmp:
                tmp.write_text(dataset_copy_text(scene_file), encoding="utf-8")
        of, livers_read = [geometry_of(scene, i, len(ids)) for i in todo], {}
        hashes = accepted_hashes(scene, out)
        tasks = [i for i, gi in zip(todo, of) if not _shard_is_done(
            shard_path(out, i), hashes, retry_failed, ids[gi], fixed[gi], livers_read)]
        tasks.sort(key=lambda i: (i % len(ids), i))  # cases of one liver together
        return Plan(tasks=tasks, skipped=len(todo) - len(tasks), geometry_ids=ids), scene
    return _guarded(plan)[0]


def _guarded(step) -> tuple[Plan, Scene | None]:
    """``step()``, with any error as Plan.error (so it is broadcast, and no rank waits for a
    plan that never comes).
    """
    try:
        return step()
    except (SceneError, GeometryError, cs.CaseError, LockedError, ValueError, OSError) as exc:
        return Plan(error=str(exc)), None
    except Exception as exc:  # unexpected: still a message on every rank, never a hang
        log.exception("planning failed")
        return Plan(error=f"{type(exc).__name__}: {exc}"), None


class _Counter:
    """Atomic counters in an MPI window on world rank 0: [next task, done, failed]."""

    def __init__(self, comm):
        from mpi4py import MPI

        self.MPI = MPI
        self.win = MPI.Win.Allocate(3 * 8 if comm.rank == 0 else 0, 8, comm=comm)
        if comm.rank == 0:
            self.win.Lock(0)
            self.win.Put(np.zeros(3, dtype="i8"), 0)
            self.win.Unlock(0)
        comm.Barrier()  # collective

    def add(self, slot: int, value: int = 1) -> int:
        out = np.zeros(1, dtype="i8")
        self.win.Lock(0)
        self.win.Fetch_and_op(np.array([value], dtype="i8"), out, 0, target_disp=slot,
                              op=self.MPI.SUM)
        self.win.Unlock(0)
        return int(out[0])

    def read(self) -> np.ndarray:
        out = np.zeros(3, dtype="i8")
        self.win.Lock(0)
        self.win.Get(out, 0)
        self.win.Unlock(0)
        return out

    def free(self):
        self.win.Free()


def _warm_jit_cache(degree: int, qdeg: int) -> None:
    """Compile the solver's forms on this process alone (fills FFCx's cache for every rank)."""
    from mpi4py import MPI

    from data_spec.geometry import box_mesh
    from fem_sim.solver.problem import OgdenProblem

    g = box_mesh(1)
    OgdenProblem(MPI.COMM_SELF, g.points, g.cells, degree=degree, quadrature_degree=qdeg)


def case_loads(case: cs.Case, g: Geometry) -> list:
    """The solver's loads of a case (at load fraction 1); none for a grasp."""
    from fem_sim.solver.loads import NodalLoad, PatchLoad

    if case.load_kind == "grasp":
        return []
    if case.load_kind == "patch":
        return [PatchLoad(g.points[node], force, case.patch_radius)
                for node, force in zip(case.load_nodes, case.forces)]
    return [NodalLoad(case.load_nodes, case.forces)]


def case_constraints(case: cs.Case, g: Geometry, fixed: np.ndarray) -> tuple[list, list]:
    """(the solver's constraints of a case, the node sets whose reaction is kept): the fixed
    region, and for a grasp each tool's patch moved rigidly by its displacement.
    """
    from fem_sim.solver.loads import Constraint

    if case.load_kind != "grasp":
        return [Constraint(fixed)], []
    patches = cs.grasp_patches(case, g, fixed)
    return ([Constraint(fixed), *(Constraint(p, values=d) for p, d in
                                  zip(patches, case.displacements))], patches)


def _solved(problem, case: cs.Case, g: Geometry, fixed: np.ndarray, fractions):
    """(solution or None, status, reason) of one case (collective); a crash is a reason."""
    try:
        constraints, tools = case_constraints(case, g, fixed)
    except cs.CaseError as exc:   # the case's own tools (a patch on the fixed region)
        return None, "failed", str(exc)
    try:
        sol = problem.solve(case.material, constraints, case_loads(case, g), fractions,
                            reactions=tools)
        return sol, sol.status, sol.failure_reason
    except Exception as exc:  # a crash of one case is recorded, never kills the batch
        log.exception("case %d crashed", case.index)
        return None, "failed", f"solver error: {type(exc).__name__}: {exc}"


def _tools(case: cs.Case, sol, n_done: int, fractions) -> dict:
    """A grasp's shard fields: each tool's displacement and reaction at the stored steps."""
    if case.load_kind != "grasp":
        return {}
    reaction = sol.reaction[:n_done] if sol is not None else np.zeros((0, len(case.forces), 3))
    return {"tool_displacement": np.asarray(fractions)[:n_done, None, None]
            * case.displacements[None], "reaction": reaction}


def run_case(problem, scene: Scene, case: cs.Case, g: Geometry, fixed: np.ndarray,
             out_nodes: np.ndarray, geometry_id: str) -> Shard | None:
    """Solve one case on the group (collective); the shard on the group's rank 0."""
    fractions = np.asarray(scene.load_fractions)
    t0 = time.perf_counter()
    sol, status, reason = _solved(problem, case, g, fixed, fractions)
    if problem.comm.rank != 0:
        return None
    if sol is None or sol.displacement is None:
        disp, stats = np.zeros((0, out_nodes.size, 3)), SolverStats.empty()
    else:
        disp = sol.displacement[:, out_nodes]
        stats = SolverStats(sol.newton_iterations, sol.residual_norms, sol.cutbacks,
                            sol.wall_time, sol.residual_history)
    stats.info = {"degree": problem.degree, "quadrature_degree": problem.qdeg,
                  "element": problem.element,
                  "linear_solver": problem.settings.linear_solver,
                  "factorization": problem.factorization,
                  "ranks": problem.comm.size,
                  **(sol if sol is not None else WorkCounts()).counts(),
                  "total_wall_time": time.perf_counter() - t0}
    if not np.all(np.isfinite(disp)):  # never NaN in a shard
        keep = np.all(np.isfinite(disp), axis=(1, 2))
        n_ok = int(np.argmin(keep)) if not keep.all() else disp.shape[0]
        disp = disp[:n_ok]
        stats = SolverStats(stats.newton_iterations[:n_ok], stats.residual_norms[:n_ok],
                            stats.cutbacks[:n_ok], stats.wall_time[:n_ok],
                            stats.residual_history[:n_ok], stats.info)
        status, reason = "failed", reason or "non-finite displacement"
    return Shard(scene_name=scene.name, scene_hash=scene.hash, sim_index=case.index,
                 seed=scene.seed, geometry_id=geometry_id, load_kind=case.load_kind,
                 load_nodes=case.load_nodes, forces=case.forces, material=case.material,
                 fixed_nodes=fixed, load_fractions=fractions, output_nodes=out_nodes,
                 displacement=disp, stats=stats, status=status, failure_reason=reason,
                 patch_radius=case.patch_radius,
                 **_tools(case, sol, disp.shape[0], fractions))


class _Liver:
    """A group's current liver and the problem on it, rebuilt when a task is on another."""

    def __init__(self, scene: Scene, plan: Plan, out: Path, group, prefix: str):
        self.scene, self.plan, self.out, self.group, self.prefix = scene, plan, out, group, prefix
        self.current = None

    def of(self, index: int) -> int:
        return geometry_of(self.scene, index, len(self.plan.geometry_ids))

    def load(self, gi: int) -> None:
        """Collective on the group when the liver changes."""
        from fem_sim.solver.problem import OgdenProblem

        if gi == self.current:
            return
        scene, solver = self.scene, self.scene["solver"]
        self.geo = read_geometry(geometry_path(self.out, self.plan.geometry_ids[gi]))
        self.fixed = cs.fixed_nodes(scene, self.geo)
        self.out_nodes = cs.output_nodes(scene, self.geo)
        self.eligible = None if scene.cases else cs.eligible_load_nodes(scene, self.geo,
                                                                         self.fixed)
        self.table = cs.material_table(scene)
        root = self.group.rank == 0
        self.problem = OgdenProblem(self.group, self.geo.points if root else None,
                                    self.geo.cells if root else None, degree=solver["degree"],
                                    quadrature_degree=solver["quadrature_degree"],
                                    element=solver.get("element", "lagrange"),
                                    settings=solver_settings(scene), prefix=self.prefix)
        self.current = gi

    def run(self, index: int) -> Shard | None:
        gi = self.of(index)
        self.load(gi)
        case = cs.make_case(self.scene, index, self.geo, self.fixed, self.table, self.eligible)
        return run_case(self.problem, self.scene, case, self.geo, self.fixed, self.out_nodes,
                        self.plan.geometry_ids[gi])


def _one_thread_per_rank(world) -> None:
    """The ranks share the cores: one point-kernel and one PARDISO thread each (a lone rank
    keeps OpenMP's default, the cores it may run on).
    """
    if world.size > 1 and not os.environ.get("OMP_NUM_THREADS"):
        from fem_sim.material import ogden_c
        from fem_sim.solver import pardiso

        ogden_c.threads(1)
        pardiso.threads(1)


def quiet_wait(world, poll_s: float = 0.05) -> None:
    """Collective: returns on every rank once all have called it; a rank waiting for another
    (rank 0 building the livers' files and their PCA or compiling the forms, a rank finishing
    its share of the livers) sleeps between polls instead of spinning a core as a blocking MPI
    call does.
    """
    request = world.Ibarrier()
    while not request.Test():
        time.sleep(poll_s)


def _plan(world, scene_file, out, only, retry_failed, progress, ranks_per_sim):
    """(plan, scene) on every rank; rank 0 checks and decides, every rank prepares its share
    of a file population's livers in between (collective).
    """
    plan, scene = Plan(), None
    if world.rank == 0:
        if world.size % ranks_per_sim:  # checked before anything is written
            plan = Plan(error=f"--ranks-per-sim {ranks_per_sim} does not divide the "
                              f"{world.size} MPI ranks")
        else:
            plan, scene = check_run(scene_file, out, only, ranks_per_sim)
    plan, scene = world.bcast((plan, scene), root=0)  # collective
    if plan.error:
        return plan, None
    shares = _prepare_share(world, scene, out, progress) if world.size > 1 else None
    if world.rank == 0:
        plan = make_plan(scene, scene_file, out, only, retry_failed, progress)
        plan.prepared = shares
    quiet_wait(world)  # collective: a population's livers take minutes on rank 0
    plan = world.bcast(plan, root=0)  # collective
    return plan, (None if plan.error else scene)


def _prepare_share(world, scene: Scene, out: Path, progress: bool) -> list[int] | None:
    """Every rank meshes and registers its share of the liver files the dataset lacks
    (:func:`fem_sim.geometry.file_population.prepare_share`); rank 0 then reads them back.
    Rank 0 lists the livers the dataset lacks, once for all. Collective; a rank that fails
    here leaves its livers to rank 0. Rank 0 gets how many each rank prepared.
    """
    from fem_sim.geometry.file_population import prepare_share, unprepared

    todo = []
    if world.rank == 0:
        try:
            todo = unprepared(scene, out)
        except Exception:  # noqa: BLE001 (rank 0 meets it again in make_plan and says why)
            log.exception("listing the livers to prepare failed; rank 0 prepares them")
    todo = world.bcast(todo, root=0)  # collective
    staged = 0
    try:
        staged = prepare_share(scene, out, todo[world.rank::world.size], world.size,
                               progress=progress and world.rank == 0)
    except Exception:  # noqa: BLE001 (never a hang: rank 0 prepares what is missing)
        log.exception("rank %d: preparing livers failed; rank 0 prepares them", world.rank)
    quiet_wait(world)  # collective: a population's livers take minutes
    return world.gather(staged, root=0)  # collective


def _work(world, group, counter, plan: Plan, liver: _Liver, bar) -> None:
    """Take tasks until none is left; each group's rank 0 writes its shards."""
    n_groups = world.size // group.size
    while True:
        pos = counter.add(0) if group.rank == 0 else None
        pos = group.bcast(pos, root=0)
        if pos >= len(plan.tasks):
            break
        index = plan.tasks[pos]
        shard = liver.run(index)
        if group.rank == 0:
            write_shard(liver.out, shard)
            counter.add(1)
            if shard.status != "ok":
                counter.add(2)
                log.warning("sim %d failed: %s", index, shard.failure_reason)
        if bar is not None:
            done, failed = counter.read()[1:]
            bar.n = int(done)
            bar.set_postfix(failed=int(failed), groups=n_groups, refresh=False)
            bar.refresh()


def _report(world, scene, plan, out, totals, elapsed, ranks_per_sim, max_failure_rate) -> int:
    """Rank 0: the batch's line, and exit code 3 when too many simulations failed."""
    done, failed = int(totals[1]), int(totals[2])
    rate = done / elapsed * 3600 if elapsed > 0 else 0.0
    print(f"fem_sim generate {scene.name}: {done} simulated ({failed} failed), "
          f"{plan.skipped} skipped (already valid), {elapsed:.1f} s, "
          f"{rate:.0f} simulations/hour on {world.size} rank(s), "
          f"{world.size // ranks_per_sim} group(s) of {ranks_per_sim}"
          + (f"; liver files prepared per rank: {plan.prepared}" if any(plan.prepared or [])
             else ""), flush=True)
    if done and failed / done > max_failure_rate:
        print(f"fem_sim generate: error: {failed} of {done} simulations failed, more than "
              f"--max-failure-rate {max_failure_rate:g}: a broken set-up rather than hard "
              f"cases. Most common reasons:\n{_failure_summary(out, plan.tasks)}",
              file=sys.stderr, flush=True)
        return 3
    return 0


def generate(scene_file: str, out: str | Path, ranks_per_sim: int = 1, only: str | None = None,
             retry_failed: bool = False, progress: bool = True,
             max_failure_rate: float = 0.5) -> int:
    """Run (or resume) a batch; returns the process exit code (0; 2 bad input, nothing done;
    3 more than ``max_failure_rate`` of the simulations failed). Collective on COMM_WORLD.
    """
    from mpi4py import MPI

    import fem_sim.solver.problem  # noqa: F401  (collective: PETSc initialises on every rank)

    world = MPI.COMM_WORLD
    out = Path(out)
    t_start = time.perf_counter()
    _one_thread_per_rank(world)
    plan, scene = _plan(world, scene_file, out, only, retry_failed, progress, ranks_per_sim)
    if plan.error:
        if world.rank == 0:
            print(f"fem_sim generate: error: {plan.error}", file=sys.stderr, flush=True)
        return 2
    if world.rank == 0:
        _warm_jit_cache(scene["solver"]["degree"], scene["solver"]["quadrature_degree"])
    quiet_wait(world)  # collective
    group = world.Split(world.rank // ranks_per_sim, world.rank)  # collective
    counter = _Counter(world)
    bar = None
    if progress and world.rank == 0 and plan.tasks:
        from tqdm import tqdm

        bar = tqdm(total=len(plan.tasks), desc=scene.name, unit="sim", file=sys.stderr,
                   dynamic_ncols=True)
    liver = _Liver(scene, plan, out, group, prefix=f"g{world.rank // ranks_per_sim}_")
    _work(world, group, counter, plan, liver, bar)
    quiet_wait(world)  # collective: every shard is written (a group done early sleeps)
    totals = counter.read() if world.rank == 0 else None
    counter.free()
    if world.rank != 0:
        return 0
    if bar is not None:
        bar.n = int(totals[1])
        bar.close()
    return _report(world, scene, plan, out, totals, time.perf_counter() - t_start,
                   ranks_per_sim, max_failure_rate)


def _failure_summary(out: Path, tasks: list[int], top: int = 3) -> str:
    """The most common failure reasons among the shards of ``tasks`` (rank 0), numbers
    replaced by # so that the same failure at other loads counts once.
    """
    import re
    from collections import Counter

    import h5py

    reasons: Counter = Counter()
    for i in tasks:
        try:
            with h5py.File(shard_path(out, i), "r") as f:
                if str(f.attrs["status"]) == "failed":
                    why = str(f.attrs["failure_reason"])
                    reasons[re.sub(r"[-+]?\d[\d.e+-]*", "#", why)[:160]] += 1
        except (OSError, KeyError):
            continue
    return "\n".join(f"  {n} x {why}" for why, n in reasons.most_common(top))
