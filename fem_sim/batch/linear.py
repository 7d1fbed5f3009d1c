"""The small-strain responses of a one-liver scene (:mod:`data_spec.linear_fields`): the
liver linearised at u = 0 under the loads of every simulation of the scene and of
``synthetic`` more cases drawn by the scene's own rule (case indices from
``SYNTHETIC_FIRST``), from one float64 factorisation of the tangent, the loads back-solved
as one block.

    python -m fem_sim linear SCENE --out DATA [--synthetic N] [--order 2] [--green]
        [--green-near "X Y Z ..." [--green-radius MM]]

What a patient model learns beside its few nonlinear simulations (:mod:`surrogate.patient`):
the exact linear elasticity of the patient's own mesh, for as many loads as it likes, at the
price of back-solves; ``--order 2`` adds each load's second-order term (the Ogden law's
first stiffening, :meth:`~fem_sim.solver.problem.OgdenProblem.load_expansion`: two internal
force assemblies and one more back-solve per load); ``--green`` adds the response to a unit
force along each axis at every surface node off the fixed region (three back-solves per node),
from which a patient model gives the exact small-strain part of any nodal load at run time;
``--green-near`` restricts those to the free surface nodes within ``--green-radius`` of the
one nearest each point (a known grasp: its patch's responses, a few dozen back-solves where
the whole surface takes thousands, the same numbers).
Runs on one process (the factorisation's threads use the cores).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from data_spec import load_scene
from data_spec.linear_fields import (
    SYNTHETIC_FIRST,
    LinearFields,
    linear_fields_path,
    write_linear_fields,
)
from fem_sim.batch import cases as cs
from fem_sim.batch.generate import _scene_livers, _write_livers, case_loads, solver_settings
from fem_sim.geometry.source import n_geometries


def _cases(scene, scene_file: str, g, fixed: np.ndarray, synthetic: int) -> list:
    """The scene's simulations and ``synthetic`` drawn cases, all of one material."""
    table = cs.material_table(scene)
    eligible = None if scene.cases else cs.eligible_load_nodes(scene, g, fixed)
    indices = [*range(scene.n_simulations), *range(SYNTHETIC_FIRST, SYNTHETIC_FIRST + synthetic)]
    out = [cs.make_case(scene, i, g, fixed, table, eligible) for i in indices]
    materials = {c.material for c in out}
    if len(materials) > 1:
        raise ValueError(f"{scene_file}: [material] varies between simulations; small-strain "
                         "responses are of one liver and one material")
    return out


GREEN_MAX_BYTES = 2 * 2**30   # the Green's function's float32 size at most


GREEN_RADIUS = 20.0   # mm: --green-near's default reach, twice a tool's default patch


def green_nodes(points: np.ndarray, surface_nodes: np.ndarray, fixed: np.ndarray,
                near: np.ndarray | None = None, radius: float = GREEN_RADIUS) -> np.ndarray:
    """The surface nodes off the fixed region (where a patient model's loads act), or with
    ``near`` (k, 3) mm only those within ``radius`` mm of the free node nearest each point:
    that node is then the nearest computed one, and every patch of radius at most ``radius``
    around it (:func:`data_spec.eligible_loads.grasp_patch`) is computed whole.
    """
    free = np.setdiff1d(surface_nodes, fixed)
    if near is None:
        return free
    x = points[free]
    keep = np.zeros(free.size, bool)
    for p in np.asarray(near, np.float64).reshape(-1, 3):
        c = x[np.argmin(np.linalg.norm(x - p, axis=1))]
        keep |= np.linalg.norm(x - c, axis=1) <= radius
    return free[keep]


def _check_near(green: bool, near, radius: float) -> None:
    """--green-near and --green-radius (:func:`green_nodes`); ValueError naming the flag."""
    if near is None:
        return
    near = np.asarray(near, np.float64)
    if not green or near.size == 0 or near.size % 3 or not np.all(np.isfinite(near)):
        raise ValueError(f"--green-near: expected X Y Z (mm, finite; a multiple of 3 numbers) "
                         f"with --green, got {near.tolist()}{'' if green else ' without'}")
    if not (np.isfinite(radius) and radius >= 0):
        raise ValueError(f"--green-radius: expected a number of mm >= 0 (0: the nearest node "
                         f"alone), got {radius}")


def _checked_request(scene_file: str, out: Path, synthetic: int, order: int,
                     green: bool, near=None, radius: float = GREEN_RADIUS):
    """The scene, every argument checked before any meshing: ``out`` writable and not a
    dataset of another scene (its responses are of the dataset's own scene); ValueError or
    SceneError naming the flag, the file or the key.
    """
    from data_spec.atomic import out_problem
    from data_spec.grown import same_but_size
    from data_spec.shards import list_shards

    if order not in (1, 2):
        raise ValueError(f"--order must be 1 or 2, got {order}")
    if synthetic < 0:
        raise ValueError(f"--synthetic must be >= 0, got {synthetic}")
    _check_near(green, near, radius)
    scene = load_scene(scene_file)
    kind = scene["loads"]["kind"]
    if kind == "grasp" and not (green and order == 1 and not synthetic and near is None):
        raise ValueError(f"{scene_file}: loads.kind = 'grasp': a grasp's small-strain response "
                         "comes from the Green's function of the free surface (G_PP f = d): "
                         "--green with --order 1, no --synthetic and no --green-near")
    if green and kind not in ("nodal", "grasp"):
        raise ValueError(f"{scene_file}: loads.kind = {kind!r}; --green gives the responses to "
                         "unit nodal forces, of a scene of nodal loads or grasps")
    if n_geometries(scene) != 1:
        raise ValueError(f"{scene_file}: [geometry] has {n_geometries(scene)} livers; small-"
                         "strain responses are of one liver (a patient's scene)")
    if scene.cases and synthetic:
        raise ValueError(f"{scene_file}: [[cases]] lists its loads; drawn cases need the "
                         "scene's load rule ([loads] without [[cases]])")
    why = out_problem(out, "--out", directory=True)
    if why:
        raise ValueError(why)
    copy = out / "scene.toml"
    if copy.exists() and list_shards(out):
        old = load_scene(copy)
        if not same_but_size(scene, old):
            raise ValueError(
                f"--out {out} holds a dataset of scene {old.name!r} (hash {old.hash[:12]}), not "
                f"of {scene_file} ({scene.name!r}, hash {scene.hash[:12]}): small-strain "
                f"responses are of the dataset's own scene (give {copy}), or use a new --out")
    return scene


def _record_scene(scene_file: str, out: Path) -> None:
    """``out/scene.toml``: the scene the responses are of, so that a reader can tell (a
    dataset of fem_sim generate keeps its own; a directory without shards takes this one).
    """
    from data_spec.atomic import write_text_atomic
    from data_spec.scene import dataset_copy_text
    from data_spec.shards import list_shards

    copy = out / "scene.toml"
    if not (copy.exists() and list_shards(out)):
        write_text_atomic(copy, dataset_copy_text(scene_file))


# The one liver problem a process built last (``fem_sim serve``'s ``prepare``: make liver has
# it built while the trainer registers the model), by its mesh's bytes and solver settings.
_PREPARED: dict = {}


def liver_problem(scene, points: np.ndarray, cells: np.ndarray):
    """The OgdenProblem (one rank) of a liver mesh with the scene's solver settings: the
    one :func:`prepare` built for the same mesh and settings, or a new one. Its
    factorisations depend on the material and the fixed nodes each use gives it.
    """
    from mpi4py import MPI

    from fem_sim.solver.problem import OgdenProblem

    solver = scene["solver"]
    kw = {"degree": solver["degree"], "quadrature_degree": solver["quadrature_degree"],
          "element": solver.get("element", "lagrange"), "settings": solver_settings(scene)}
    key = (np.asarray(points).tobytes(), np.asarray(cells).tobytes(), repr(sorted(
        (k, repr(v)) for k, v in kw.items())))
    if _PREPARED.get("key") != key:
        _PREPARED.clear()
        _PREPARED.update(key=key, problem=OgdenProblem(MPI.COMM_SELF, points, cells, **kw))
    return _PREPARED["problem"]


def prepare(mesh: str | Path, scene_file: str | Path) -> None:
    """Build the liver problem of a meshed liver (``fem_sim mesh``'s file) with the scene's
    solver settings (:func:`liver_problem`), for a later ``linear`` in the same process.
    """
    from data_spec.geometry import read_geometry

    g = read_geometry(mesh)
    liver_problem(load_scene(scene_file), g.points, g.cells)


def linear_fields(scene_file: str | Path, out: str | Path, synthetic: int = 0,
                  order: int = 1, green: bool = False, near=None,
                  radius: float | None = None) -> Path:
    """``out/linear.h5`` for the one-liver scene ``scene_file`` (its liver meshed and checked
    as ``fem_sim generate`` does it, into the same dataset directory ``out``); ``near``,
    ``radius`` (default ``GREEN_RADIUS``): the Green's function's nodes (:func:`green_nodes`).
    """
    radius = GREEN_RADIUS if radius is None else radius
    from fem_sim.solver.loads import Constraint

    scene_file, out = str(scene_file), Path(out)
    scene = _checked_request(scene_file, out, synthetic, order, green, near, radius)
    livers = _scene_livers(scene, out, progress=False)
    ids, fixed = _write_livers(scene, scene_file, livers, out)
    g, fixed = livers[0], fixed[0]
    cases = _cases(scene, scene_file, g, fixed, synthetic)
    nodes = cs.output_nodes(scene, g)
    gnodes = green_nodes(g.points, g.surface_nodes, fixed, near, radius) if green else None
    gf = None
    size = 0 if gnodes is None else gnodes.size * 36 * nodes.size   # float32 bytes
    if size > GREEN_MAX_BYTES:
        raise ValueError(f"{scene_file}: --green would hold {gnodes.size} x 3 unit responses "
                         f"at {nodes.size} output nodes ({size / 2**30:.1f} GiB), beyond "
                         f"{GREEN_MAX_BYTES / 2**30:.0f} GiB: a coarser mesh ([geometry] "
                         "mesh_size), or no --green")
    t = time.perf_counter()
    problem = liver_problem(scene, g.points, g.cells)
    tool_force = None
    if scene["loads"]["kind"] == "grasp":   # each case's response from the Green's function
        gf = problem.unit_responses(cases[0].material, [Constraint(fixed)],
                                    gnodes)[:, :, nodes]
        u, tool_force = _grasps_over(gf, gnodes, nodes,
                                     [cs.grasp_patches(c, g, fixed) for c in cases],
                                     [c.displacements for c in cases])
        u = u[:, None]
    else:
        loads = [case_loads(c, g) for c in cases]
        u = problem.load_expansion(cases[0].material, [Constraint(fixed)], loads,
                                   order=order)[:, :, nodes]
        if green:   # the same factorisation (kept by solve_recurring)
            gf = problem.unit_responses(cases[0].material, [Constraint(fixed)],
                                        gnodes)[:, :, nodes]
    _record_scene(scene_file, out)
    return write_linear_fields(linear_fields_path(out), LinearFields(
        case_index=np.array([c.index for c in cases], np.int64),
        load_nodes=np.stack([c.load_nodes for c in cases]),
        forces=np.stack([c.forces for c in cases]), output_nodes=nodes,
        displacement=u[:, 0], scene_name=scene.name, scene_hash=scene.hash,
        geometry_id=ids[0], seconds=time.perf_counter() - t,
        second_order=u[:, 1] if order == 2 else None, green_nodes=gnodes, green=gf,
        fixed_nodes=np.asarray(fixed, np.int64) if green else None, tool_force=tool_force))


def _grasps_over(green, rows, nodes, patches: list, pulls: list) -> tuple:
    """((cases, n_out, 3) mm, (cases, n_tools, 3) N): each grasp's small-strain field at the
    output ``nodes`` and its tools' forces, its tools holding ``patches`` (per case, a list of
    node sets) moved by ``pulls`` (per case, (n_tools, 3) mm), over the Green's function
    ``green`` with rows at the mesh nodes ``rows`` (:class:`data_spec.green_grasp.GreenGrasp`).
    """
    from data_spec.green_grasp import GreenGrasp

    both = [GreenGrasp(green, rows, nodes, ps)(d) for ps, d in zip(patches, pulls)]
    return np.stack([u for u, _ in both]), np.stack([f for _, f in both])


def _liver_shards(data: Path) -> dict:
    """{geometry id: [shards]} of a dataset's complete simulations, in simulation order."""
    from data_spec.shards import list_shards, read_shard

    out: dict = {}
    for path in list_shards(data):
        try:
            sh = read_shard(path)
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{path}: cannot be read (truncated or corrupt?): {exc}; `python -m "
                             f"data_spec validate {data}` lists every problem, `fem_sim "
                             f"generate {data}/scene.toml --out {data}` redoes it") from None
        if sh.status == "ok":
            out.setdefault(sh.geometry_id, []).append(sh)
    return out


def _liver_file_done(data: Path, gid: str, shards: list, order: int) -> bool:
    """Whether liver ``gid``'s file of the dataset ``data`` holds its responses of these
    simulations to ``order`` (a file of order 2 holds the first-order responses too), made
    for this dataset's scene and liver.
    """
    from data_spec.linear_fields import read_dataset_linear

    try:
        lf = read_dataset_linear(data, gid)
    except ValueError:
        return False
    return lf.order >= order and set(lf.case_index.tolist()) == {s.sim_index for s in shards}


def _one_liver(data: Path, gid: str, shards: list, order: int) -> Path:
    """The responses of one liver of a population dataset under its simulations' loads."""
    from mpi4py import MPI

    from data_spec.geometry import read_geometry
    from data_spec.shards import geometry_path
    from fem_sim.solver.loads import Constraint, NodalLoad
    from fem_sim.solver.problem import OgdenProblem

    scene = load_scene(data / "scene.toml")
    if scene["loads"]["kind"] not in ("nodal", "grasp"):
        raise ValueError(f"{data}/scene.toml: loads.kind = {scene['loads']['kind']!r}; the "
                         "population's small-strain responses are of nodal loads or grasps")
    g, first = read_geometry(geometry_path(data, gid)), shards[0]
    if len({s.material for s in shards}) > 1:
        raise ValueError(f"{data}: liver {gid}: its simulations' materials differ; small-"
                         "strain responses are of one material")
    solver, t = scene["solver"], time.perf_counter()
    problem = OgdenProblem(MPI.COMM_SELF, g.points, g.cells, degree=solver["degree"],
                           quadrature_degree=solver["quadrature_degree"],
                           element=solver.get("element", "lagrange"),
                           settings=solver_settings(scene))
    nodes = first.output_nodes
    tool_force = None
    if scene["loads"]["kind"] == "grasp":
        u, tool_force = _grasp_responses(problem, first, shards, g,
                                         scene["loads"]["patch_radius"])
        u = u[:, None]
    else:
        loads = [[NodalLoad(s.load_nodes, s.forces)] for s in shards]
        u = problem.load_expansion(first.material, [Constraint(first.fixed_nodes)], loads,
                                   order=order)[:, :, nodes]
    return write_linear_fields(linear_fields_path(data, gid), LinearFields(
        case_index=np.array([s.sim_index for s in shards], np.int64),
        load_nodes=np.stack([s.load_nodes for s in shards]),
        forces=np.stack([s.forces for s in shards]), output_nodes=nodes,
        displacement=u[:, 0], scene_name=scene.name, scene_hash=scene.hash, geometry_id=gid,
        seconds=time.perf_counter() - t, second_order=u[:, 1] if order == 2 else None,
        tool_force=tool_force))


def _grasp_responses(problem, first, shards: list, g, radius: float) -> tuple:
    """((len(shards), n_out, 3) mm, (len(shards), n_tools, 3) N): each grasp simulation's
    small-strain response at load fraction 1 at the output nodes and its tools' forces, from
    the Green's function rows of the liver's tools' patches (one factorisation, three
    back-solves a patch node): G_PP f = d per simulation
    (:class:`data_spec.green_grasp.GreenGrasp`; the rows are those of the free surface, so a
    patch is held exactly as the solver holds it).
    """
    from data_spec.eligible_loads import grasp_patch
    from fem_sim.solver.loads import Constraint

    patches = [[grasp_patch(g.points, g.surface_nodes, n, radius) for n in s.load_nodes]
               for s in shards]
    held = np.unique(np.concatenate([p for ps in patches for p in ps]))
    nodes = first.output_nodes
    green = problem.unit_responses(first.material, [Constraint(first.fixed_nodes)],
                                   held)[:, :, nodes]
    return _grasps_over(green, held, nodes, patches,
                        [s.tool_displacement[-1] / s.load_fractions[-1] for s in shards])


def population_linear_fields(data: str | Path, order: int = 2, progress: bool = True) -> list:
    """``data/linear/<geometry id>.h5`` for every liver of the population dataset ``data``:
    each liver's small-strain responses under its own complete simulations' loads (what the
    FE fields are compared with, liver by liver). Livers whose file is already whole are
    skipped; under ``mpirun -n N`` the ranks share the livers (one factorisation per liver on
    one process each). Returns the files this rank wrote.
    """
    from mpi4py import MPI

    data, world = Path(data), MPI.COMM_WORLD
    if order not in (1, 2):
        raise ValueError(f"--order must be 1 or 2, got {order}")
    if not (data / "scene.toml").exists():
        raise ValueError(f"{data}: no scene.toml: not a dataset directory of fem_sim generate")
    if load_scene(data / "scene.toml")["loads"]["kind"] == "grasp" and order != 1:
        raise ValueError(f"{data}: a grasp dataset: its small-strain responses are of order 1 "
                         "(a grasp's second-order term is not built): --order 1")
    livers = None
    if world.rank == 0:
        try:
            livers = _liver_shards(data)
        except ValueError as exc:
            livers = str(exc)
    livers = world.bcast(livers, root=0)   # collective: every rank the same list, or error
    if isinstance(livers, str):
        raise ValueError(livers)
    todo = [gid for gid in sorted(livers) if not _liver_file_done(data, gid, livers[gid],
                                                                  order)]
    mine, written = todo[world.rank::world.size], []
    bar = None
    if progress and world.rank == 0:
        from tqdm import tqdm
        bar = tqdm(total=len(mine), unit="liver", desc="small-strain responses (rank 0)",
                   file=sys.stderr)
    for gid in mine:
        written.append(_one_liver(data, gid, livers[gid], order))
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    world.Barrier()   # collective: every liver written before any rank returns
    return written
