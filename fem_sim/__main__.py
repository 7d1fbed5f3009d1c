"""Command line of fem_sim.

mpirun -n N python3 -m fem_sim generate SCENE.toml --out DIR [--ranks-per-sim R]
[--only I..J] [--retry-failed]
python3 -m fem_sim summary DIR
python3 -m fem_sim population SCENE.toml --out DIR   (scene 4: CPD + PCA shape coefficients)
python3 -m fem_sim phantom SEED --out FILE.h5 [--variety V] [--spread S] [--mesh-size H]
python3 -m fem_sim linear SCENE.toml --out DIR [--synthetic N] [--order 2] [--green]
        [--green-near "X Y Z ..." [--green-radius MM]]
    (a one-liver scene's small-strain responses, DIR/linear.h5)
python3 -m fem_sim linear --population DATA [--order 2]
    (every liver of a population dataset under its simulations' loads, DATA/linear/)
python3 -m fem_sim serve
    (these commands as JSON lines on stdin, one answer a line: fem_sim/serve.py)
"""

from __future__ import annotations

import argparse
import logging
import sys

EPILOG = """\
generate: turns a scene (data_spec/scenes/*.toml) into one shard per simulation in DIR/sims,
with the meshes in DIR/geometry. Run it under mpirun: the N ranks form N/R groups of R ranks;
each group solves whole simulations (domain decomposition inside a group) and takes the next
case dynamically. The same dataset comes out for any N and R. Re-running the same command skips
valid shards and redoes missing or corrupt ones; failed simulations are kept (with their reason
and converged steps) and only retried with --retry-failed. One run at a time per directory (a
lock). Exit code 2: bad scene or mesh, or the directory is in use (nothing was computed); 3:
more than --max-failure-rate of the simulations failed (a broken set-up: the most common
reasons are printed); 1: a rank failed and all ranks were aborted; 0 otherwise.
"""


def _collective(run) -> int:
    """Run an MPI-collective command so that an error on any rank ends every rank: the rank
    prints what happened and calls MPI_Abort (no rank waits forever for a message that will
    never come). Covers SystemExit raised inside libraries too (meshio calls sys.exit).
    """
    try:
        return run()
    except BaseException as exc:
        from mpi4py import MPI

        world = MPI.COMM_WORLD
        if world.size == 1 or (isinstance(exc, SystemExit) and exc.code in (0, None)):
            raise
        import traceback

        print(f"fem_sim: rank {world.rank}: fatal {type(exc).__name__}: {exc}; aborting all "
              f"{world.size} ranks", file=sys.stderr, flush=True)
        traceback.print_exc()
        world.Abort(1)
        raise  # not reached


# What each command imports that only the solver environment has.
NEEDS = {"generate": "dolfinx", "linear": "dolfinx", "population": "gmsh", "phantom": "gmsh",
         "mesh": "gmsh"}


def wrong_environment(command: str) -> str | None:
    """Why ``command`` cannot run in this Python (None when it can): the trainer environment
    has neither dolfinx nor gmsh.
    """
    import importlib.util

    module = NEEDS.get(command)
    if module is None or importlib.util.find_spec(module) is not None:
        return None
    return (f"liverfem-sim {command}: {module} is not importable by {sys.executable}: this "
            f"command runs in the solver environment (.venv-solver/bin/python -m fem_sim "
            f"{command}, or make dataset / make population); the trainer environment runs "
            "liverfem-surrogate")


def _mesh_parser(sub) -> None:
    from data_spec.checks import positive_number, scale_factor

    me = sub.add_parser("mesh", help="repair and mesh one liver surface (CT segmentations: "
                        "holes, crossing triangles, pieces) into a data_spec geometry file, "
                        "with its repair report and a picture")
    me.add_argument("liver", help="surface file: .obj .stl .ply .vtk .vtp")
    size = me.add_mutually_exclusive_group(required=True)
    size.add_argument("--mesh-size", type=positive_number, metavar="H", help="mm")
    size.add_argument("--scene", help="a population scene: its mesh size and scale, so that "
                      "the liver is meshed as that population's livers were (surrogate "
                      "truth-scene --mesh places a model on it)")
    me.add_argument("--out", required=True, help="geometry file to write (.h5)")
    me.add_argument("--scale-to-mm", type=scale_factor, default=1.0,
                    help="multiply the file's coordinates by this (1000 for metres; > 0: a "
                    "negative scale would mirror the liver)")
    me.add_argument("--keep-largest", action="store_true",
                    help="keep the largest piece of a file holding several large ones (by "
                    "default refused: two livers, or a liver in parts)")
    me.add_argument("--no-picture", action="store_true")


def _parser() -> argparse.ArgumentParser:
    from data_spec.checks import count, positive_number

    parser = argparse.ArgumentParser(prog="python3 -m fem_sim", epilog=EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate", help="generate a dataset from a scene (run under mpirun)",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    g.add_argument("scene", help="scene TOML file")
    g.add_argument("--out", required=True, help="dataset directory (created or resumed)")
    g.add_argument("--ranks-per-sim", type=int, default=1, metavar="R",
                   help="MPI ranks that share one simulation (default 1)")
    g.add_argument("--only", metavar="I..J", help="only simulations I <= i < J")
    g.add_argument("--retry-failed", action="store_true",
                   help="also redo simulations recorded as failed")
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    g.add_argument("--max-failure-rate", type=float, default=0.5, metavar="F",
                   help="exit with code 3 when more than this fraction of the simulations "
                        "fail (default 0.5; 1 for sweeps of extremes)")
    sub.add_parser("population", help="scene 4: CPD + PCA shape coefficients of a liver "
                   "population, with the IoU/Dice report (see population --help)")
    ph = sub.add_parser("phantom", help="mesh one phantom liver into a data_spec geometry "
                        "file (a liver to try predict-liver or a file scene on)")
    ph.add_argument("seed", type=int)
    ph.add_argument("--out", required=True, help="geometry file to write (.h5)")
    ph.add_argument("--variety", choices=("anatomical", "narrow"), default="anatomical")
    ph.add_argument("--spread", type=float, default=1.0, metavar="S",
                    help="an anatomical phantom's shape ranges widened by S about their "
                         "centres (default 1: the population's)")
    ph.add_argument("--mesh-size", type=positive_number, default=16.0, metavar="H",
                    help="target edge length, mm (default 16, the shipped scenes')")
    _mesh_parser(sub)
    li = sub.add_parser("linear", help="small-strain responses of a one-liver scene (its "
                        "liver linearised at u = 0) under its simulations' loads and N drawn "
                        "ones: DIR/linear.h5, what a patient model learns from")
    li.add_argument("scene", nargs="?", help="scene TOML file (one liver, one material)")
    li.add_argument("--out", help="dataset directory (its liver meshed there)")
    li.add_argument("--population", metavar="DATA",
                    help="instead: every liver of the population dataset DATA under its own "
                    "simulations' loads, DATA/linear/<geometry id>.h5 (ranks share livers)")
    li.add_argument("--synthetic", type=count, default=0, metavar="N",
                    help="loads drawn by the scene's rule beside its simulations' (default 0)")
    li.add_argument("--order", type=int, default=1, choices=(1, 2),
                    help="2: each response's second-order term in the load too (default 1)")
    li.add_argument("--green", action="store_true",
                    help="also the response to a unit force at every surface node off the "
                    "fixed region (a patient model's exact small-strain part)")
    li.add_argument("--green-near", metavar="'X Y Z ...'",
                    help="with --green: only the free surface nodes within --green-radius of "
                    "the one nearest each point (mm, one quoted list; a known grasp's patch, "
                    "in seconds)")
    li.add_argument("--green-radius", type=float, metavar="MM",
                    help="--green-near's reach, mm (default 20: a 20 mm patch fits; 0: "
                    "the nearest node alone)")
    s = sub.add_parser("summary", help="print counts and statistics of a dataset")
    s.add_argument("directory")
    s.add_argument("--png", help="picture of deformed livers (default DIR/summary.png)")
    return parser


def _generate(args, parser) -> int:
    from pathlib import Path

    if args.ranks_per_sim < 1:
        parser.error("--ranks-per-sim must be >= 1")
    if not 0.0 <= args.max_failure_rate <= 1.0:
        parser.error("--max-failure-rate must be in [0, 1]")
    if Path(args.out).exists() and not Path(args.out).is_dir():
        parser.error(f"--out {args.out} is a file; expected the dataset's directory "
                     "(created if missing)")
    from fem_sim.batch.generate import generate

    return _collective(lambda: generate(
        args.scene, args.out, args.ranks_per_sim, args.only, args.retry_failed,
        progress=not args.no_progress, max_failure_rate=args.max_failure_rate))


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    argv = sys.argv[1:] if argv is None else argv
    why = wrong_environment(argv[0]) if argv else None
    if why:
        print(why, file=sys.stderr)
        return 2
    if argv[:1] == ["serve"]:   # commands as JSON lines from a trainer process
        from fem_sim.serve import serve

        return serve(main)
    if argv[:1] == ["population"]:
        from fem_sim.batch.population_cli import main as population_main

        return population_main(argv[1:])
    logging.getLogger().setLevel(logging.WARNING)  # FFCx's JIT logs to the root logger
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command == "generate":
        return _generate(args, parser)
    if args.command == "phantom":
        return _phantom(args, parser)
    if args.command == "linear":
        return _linear(args)
    if args.command == "mesh":
        from fem_sim.geometry.mesh_command import mesh_size_of, run

        size, scale = mesh_size_of(args)
        if size is None:
            return 2
        return run(args.liver, size, args.out, scale, picture=not args.no_picture,
                   keep_largest=args.keep_largest)
    from fem_sim.batch.summary import summary

    return summary(args.directory, png=args.png)


def _numbers(flag: str, text: str | None) -> list[float] | None:
    """A quoted list of numbers, or None; ValueError naming the flag and the word."""
    if text is None:
        return None
    try:
        return [float(w) for w in text.replace(",", " ").split()]
    except ValueError:
        raise ValueError(f"{flag}: expected numbers (mm), got {text!r}") from None


def _linear(args) -> int:
    from data_spec import SceneError
    from fem_sim.batch.linear import linear_fields
    from fem_sim.geometry.errors import GeometryError

    if (args.population is None) == (args.scene is None or args.out is None):
        print("fem_sim linear: give SCENE --out DIR, or --population DATA", file=sys.stderr)
        return 2
    try:
        if args.population is not None:
            from fem_sim.batch.linear import population_linear_fields

            if args.synthetic or args.green or args.green_near:
                raise ValueError("--population takes the simulations' loads only (no "
                                 "--synthetic, no --green)")
            written = population_linear_fields(args.population, args.order)
            print(f"{args.population}/linear: {len(written)} livers written by this rank")
            return 0
        near = _numbers("--green-near", args.green_near)
        path = linear_fields(args.scene, args.out, args.synthetic, args.order, args.green,
                             near, args.green_radius)
    except (SceneError, GeometryError, ValueError, OSError) as exc:
        print(f"fem_sim linear: {exc}", file=sys.stderr)
        return 2
    print(f"{path}: small-strain responses of {args.scene}")
    return 0


def _phantom(args, parser) -> int:
    from pathlib import Path

    from data_spec.atomic import out_problem
    from data_spec.geometry import write_geometry
    from fem_sim.geometry.errors import GeometryError
    from fem_sim.geometry.phantom import make_phantom

    out = Path(args.out)
    if out.suffix not in (".h5", ".hdf5"):
        parser.error(f"--out {out}: expected a .h5 data_spec geometry file")
    why = out_problem(out)
    if why:
        parser.error(why)
    try:
        g = make_phantom(args.seed, args.mesh_size, args.variety, args.spread)
    except (ValueError, GeometryError) as exc:
        print(f"fem_sim phantom: {exc}", file=sys.stderr)
        return 2
    out.parent.mkdir(parents=True, exist_ok=True)
    write_geometry(out, g)
    print(f"{out}: {g.description.split(', parameters')[0]}; {g.n_nodes} nodes, "
          f"{g.cells.shape[0]} tetrahedra")
    return 0


if __name__ == "__main__":
    sys.exit(main())
