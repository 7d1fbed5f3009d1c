"""The trainer's command line (``liverfem-surrogate``, or ``python -m surrogate``).

    train --data DIR --run RUN [--config NAME] [--fresh] [key=value ...]
    predict-liver [RUN] LIVER --force X Y Z FX FY FZ [--out DIR]
    truth-scene RUN LIVER --scene SCENE [--sims N] --out FILE [--placement NPZ] [--mesh H5]
    evaluate RUN DATA [--liver LIVER [--mesh H5]] [--population DIR] [--out FILE]
    adapt RUN DATA --liver LIVER --run OUT [--sims K] [--synthetic N] [--placement NPZ] [--tune]
          [--rest RUN]

A killed training resumes when the same command is run again (``--fresh`` starts over).
``truth-scene`` writes the scene of a liver's FE truth with the model's boundary condition
(``fem_sim generate`` solves it in the solver environment); ``evaluate`` compares a model with
any dataset: one of its own liver, or that truth of a liver it never saw. ``adapt`` turns a
population model and a patient's FE simulations (that truth) into the patient's own model
(:mod:`surrogate.patient`; ``make patient`` runs the three steps).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from data_spec.checks import count

FRAMES = ("LPS", "RAS", "population", "auto")


def _value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _add_train(sub) -> None:
    t = sub.add_parser("train", help="k-fold CV, metrics, plots and an exported model")
    t.add_argument("--data", required=True, help="dataset directory written by fem_sim")
    t.add_argument("--run", required=True, help="run directory to write")
    t.add_argument("--config", help="config name (default: the scene's surrogate.config)")
    t.add_argument("--fresh", action="store_true",
                   help="discard RUN/checkpoints instead of resuming from them")
    t.add_argument("overrides", nargs="*", metavar="key=value",
                   help="config overrides, e.g. epochs=20 hidden=[64,64]")


def _add_predict_liver(sub) -> None:
    from liverreg.shape_model import SHAPE_RULES

    p = sub.add_parser("predict-liver", help="place a liver never seen in the training "
                       "population and predict its displacement (models of scene 4)")
    p.add_argument("paths", nargs="+", metavar="[RUN] LIVER",
                   help="a run directory whose model was trained on a population (default: "
                   "the shipped one, models/: of grasps with --grasp, of forces over the "
                   "liver's base with --base, else the population basis), and the liver: a "
                   "surface (.vtk .vtp .stl .obj .ply) or a volume mesh (.vtu, .vtk, "
                   "data_spec .h5), in mm")
    p.add_argument("--force", nargs=6, type=float, action="append", default=[],
                   metavar=("X", "Y", "Z", "FX", "FY", "FZ"),
                   help="a force FX FY FZ (N) at the liver surface point nearest to X Y Z "
                   "(mm); once per load of the model. Without it the manipulator (a window) "
                   "opens on the placed liver (with --base, over its Green's function)")
    p.add_argument("--out", default="predict-liver", help="output directory")
    p.add_argument("--scale-to-mm", type=float, default=1.0,
                   help="multiply the file's coordinates by this (1000 for metres)")
    p.add_argument("--no-center", action="store_true",
                   help="keep the liver where the file puts it (a liver already in the "
                   "population's frame and place); by default it is mapped onto the "
                   "population's mean liver (--frame)")
    p.add_argument("--frame", choices=FRAMES, default=None,
                   help="the liver file's frame: LPS (DICOM, ITK), RAS (NIfTI, "
                   "Slicer), population (x toward the right lobe, y posterior, z up), or auto "
                   "(the best rigid fit onto the population's mean liver, mirror images "
                   "included; it may turn a liver unlike the population's away from its "
                   "anatomy); default: the population's liver files' frame, LPS for phantoms")
    p.add_argument("--shape", choices=SHAPE_RULES,
                   help="the shape the network is told for a liver outside the population: "
                   "own, range, radius, hull or outside (docs/shape_rule.md); default: the "
                   "design's")
    p.add_argument("--no-picture", action="store_true", help="no PNG (no OpenGL needed)")
    p.add_argument("--base", metavar="DATA",
                   help="the liver's own mesh and small-strain Green's function (fem_sim "
                   "linear --green on its truth-scene, as make liver runs it): the whole field "
                   "on that mesh, of a model of the rest over it (config population_green)")
    p.add_argument("--grasp", nargs=6, type=float, action="append", default=[],
                   metavar=("X", "Y", "Z", "DX", "DY", "DZ"),
                   help="with --base, instead of --force: a tool grasping the 10 mm patch "
                   "around the liver surface point nearest to X Y Z (mm) and moving it by DX "
                   "DY DZ (mm); once or twice. The field and each tool's force: the "
                   "small-strain base over the liver's Green's function, a model of grasps' "
                   "rest added and its force stiffened (docs/surgical_loads.md)")
    p.add_argument("--patient", metavar="RUN",
                   help="with --base and --grasp: a patient's corrections of the model of "
                   "grasps (make patient LOAD=grasp's run: its force's and its field's "
                   "correction), on that patient's DATA")
    p.add_argument("--placement", help="with --base: the placement file truth-scene "
                   "--placement wrote (read when it holds this liver, frame and model)")


def _add_evaluate(sub) -> None:
    s = sub.add_parser("truth-scene", help="the scene of a liver's FE truth with a population "
                       "model's boundary condition (solve it with fem_sim generate)")
    s.add_argument("run", help="a run directory whose model was trained on a population")
    s.add_argument("liver", help="the liver file (as predict-liver reads it)")
    s.add_argument("--scene", required=True, help="the population scene whose loads, "
                   "material, steps and solver the truth takes")
    s.add_argument("--sims", type=int, default=60, help="simulations of the truth")
    s.add_argument("--frame", choices=FRAMES, default=None, help="as predict-liver's")
    s.add_argument("--out", required=True, help="the scene file to write")
    s.add_argument("--near", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="draw the loads around this site (mm, the liver file's frame): a "
                   "patient's planned grasp ([loads] near)")
    s.add_argument("--near-radius", type=float, metavar="MM",
                   help="with --near: the reach (default 20 mm)")
    s.add_argument("--placement", help="keep the liver's placement in this .npz file (adapt "
                   "--placement reads it instead of placing the liver again)")
    s.add_argument("--mesh", help="the liver file meshed as the population's livers were "
                   "(liverfem-sim mesh LIVER --scene SCENE --out FILE.h5): the template is "
                   "registered on it as on theirs (make liver, patient and truth do this)")
    e = sub.add_parser("evaluate", help="a trained model against a dataset it never trained "
                       "on: of its own liver, or the FE truth of a liver it never saw (a "
                       "model of a base's rest over the base of the truth's mesh, and the "
                       "base alone)")
    e.add_argument("run", help="a run directory (or its model directory)")
    e.add_argument("data", help="a dataset directory written by fem_sim generate")
    e.add_argument("--liver", help="the liver file the dataset was solved on, for a "
                   "population model (it is placed as predict-liver places it)")
    e.add_argument("--frame", choices=FRAMES, default=None, help="as predict-liver's")
    e.add_argument("--mesh", help="with --liver: the meshed liver truth-scene --mesh placed "
                   "the model on")
    e.add_argument("--population", help="the population dataset whose mean displacement is "
                   "the naive model (default: the evaluated dataset's own mean)")
    e.add_argument("--out", help="write the metrics here as JSON")


def _patient_arguments(p) -> None:
    """What adapt and evaluate-patient both take: the population model, the patient's FE
    truth, its liver file and frame, the rest model and the fine-tuning switch.
    """
    p.add_argument("model", help="the population model's run directory")
    p.add_argument("data", help="the patient's FE simulations (truth-scene, then fem_sim "
                   "generate and fem_sim linear)")
    p.add_argument("--liver", required=True, help="the liver file they were solved on")
    p.add_argument("--frame", choices=FRAMES, default=None, help="as predict-liver's")
    p.add_argument("--tune", action="store_true",
                   help="fine-tune the population network on the simulations before the "
                   "correction (docs/patient.md measures it)")
    p.add_argument("--rest", metavar="RUN",
                   help="a population model of what each liver's small-strain base misses "
                   "(config population_linear), added to the patient's own base")


def _add_adapt(sub) -> None:
    a = sub.add_parser("adapt", help="a patient's own model: a population model corrected "
                       "with FE simulations of the patient's liver, as a one-liver model")
    _patient_arguments(a)
    a.add_argument("--run", required=True, help="the patient model's run directory to write")
    a.add_argument("--sims", type=int, help="use the first K simulations (default: all)")
    # the default is surrogate.patient.SYNTHETIC, read when the command runs: building the
    # parser of every command does not import the trainer
    a.add_argument("--synthetic", type=int, default=None,
                   help="loads drawn for the distillation (default: surrogate.patient's "
                   "SYNTHETIC)")
    a.add_argument("--placement", help="the placement file truth-scene --placement wrote "
                   "(used when it holds this liver, frame and model; written otherwise)")


def _add_evaluate_patient(sub) -> None:
    e = sub.add_parser("evaluate-patient", help="a patient model against K: made from the "
                       "first K of the patient's FE simulations, measured on those held out")
    _patient_arguments(e)
    e.add_argument("--results", required=True, help="where each K's patient model and the "
                   "kept errors go (a second call computes only what is new)")
    e.add_argument("--ks", type=count, nargs="+", default=[0, 5, 10, 20, 40],
                   help="the K measured (default 0 5 10 20 40)")
    e.add_argument("--held", type=count, default=10, help="the first HELD simulations are "
                   "held out, the same for every K (default 10)")
    e.add_argument("--out", help="write the errors here as JSON")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="liverfem-surrogate")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_train(sub)
    _add_predict_liver(sub)
    _add_evaluate(sub)
    _add_adapt(sub)
    _add_evaluate_patient(sub)
    return parser


def _fail(command: str, message: str) -> int:
    print(f"liverfem-surrogate {command}: {message}", file=sys.stderr)
    return 2


def _predict_liver(args) -> int:
    from surrogate.shipped import BASIS, FORCES, GRASPS

    if len(args.paths) > 2:
        return _fail("predict-liver", f"expected [RUN] LIVER, got {len(args.paths)} paths")
    shipped = GRASPS if args.grasp else FORCES if args.base else BASIS
    args.run, args.liver = ([shipped] + args.paths)[-2:]
    if args.grasp and not args.base:
        return _fail("predict-liver", "--grasp needs --base (the liver's own mesh and Green's "
                     "function: make liver GRASP=...)")
    if args.patient and not (args.base and args.grasp):
        return _fail("predict-liver", "--patient corrects a model of grasps: it needs --base "
                     "(the patient's data) and --grasp")
    if args.base and args.no_center:
        return _fail("predict-liver", "--base takes a centred placement (no --no-center: the "
                     "liver's mesh is placed as truth-scene placed it)")
    if not (args.force or args.grasp):  # no load: the manipulator opens on the placed liver
        from surrogate.viewer import main as viewer

        if args.base:   # over the liver's own Green's function, as make liver answers
            return viewer([str(args.run), "--place", str(args.liver), "--base", str(args.base),
                           *(["--frame", args.frame] if args.frame else [])])
        return viewer([str(args.run), "--place", str(args.liver), "--scale-to-mm",
                       str(args.scale_to_mm),
                       *(["--frame", args.frame] if args.frame else []),
                       *(["--shape", args.shape] if args.shape else [])]
                      + (["--no-center"] if args.no_center else []))
    from surrogate.predict_liver import main as predict_liver

    over = None
    if args.base:   # the liver's own mesh and Green's function (make liver)
        from surrogate.over_green import predict_over_green
        from surrogate.patient.grasps import PatientGrasp

        try:
            patient = PatientGrasp.load(args.patient) if args.patient else None
        except ValueError as exc:
            return _fail("predict-liver", str(exc))

        def over(predictor, forces, at):
            return predict_over_green(predictor, args.base, args.liver, forces, at,
                                      frame=args.frame, saved=args.placement,
                                      shape=args.shape, grasp=bool(args.grasp),
                                      patient=patient)[0]
    return predict_liver(args, over)


def _train_config(args, scene):
    """(config, None) for the train command, or (None, the reason it cannot run)."""
    from surrogate.config import get_config
    from surrogate.designs import DESIGNS

    bad = [kv for kv in args.overrides if "=" not in kv]
    if bad:
        return None, f"overrides are key=value, got {bad}"
    overrides = {k: _value(v) for k, v in (kv.split("=", 1) for kv in args.overrides)}
    name = args.config or scene["surrogate"]["config"]
    overrides.setdefault("folds", scene["surrogate"]["folds"])
    overrides.setdefault("node_fraction", scene["surrogate"]["node_fraction"])
    try:
        cfg = get_config(name, **overrides)
    except ValueError as exc:
        return None, str(exc)
    why = DESIGNS[cfg["design"]].scene_problem(scene.varies["geometry"])
    if why:
        return None, f"config {name!r}: {why} ({args.data}/scene.toml)"
    return cfg, None


def _train(args) -> int:
    from data_spec import SceneError, load_scene
    from surrogate.data import DataError
    from surrogate.train import train_and_evaluate

    try:
        scene = load_scene(Path(args.data) / "scene.toml")
    except SceneError as exc:
        return _fail("train", str(exc))
    cfg, why = _train_config(args, scene)
    if why:
        return _fail("train", why)
    if Path(args.run).exists() and not Path(args.run).is_dir():
        return _fail("train", f"--run {args.run} is a file, not a directory")
    try:
        result = train_and_evaluate(args.data, args.run, cfg, fresh=args.fresh)
    except (DataError, OSError) as exc:  # OSError: a run directory that cannot be written
        return _fail("train", str(exc))
    print(json.dumps({k: result[k] for k in ("scene", "skill", "training_seconds")}))
    return 0


def _check_site(args) -> None:
    """ValueError naming --near when the site is not finite or no surface node of the liver
    (its --mesh, or its file) lies within the reach.
    """
    import numpy as np

    from data_spec.eligible_loads import NEAR_RADIUS
    from surrogate.predict_liver import read_liver_surface

    if args.near is None:
        return
    reach = args.near_radius or NEAR_RADIUS
    if not (np.all(np.isfinite(args.near)) and np.isfinite(reach) and reach > 0):
        raise ValueError(f"--near {args.near} --near-radius {args.near_radius}: expected a "
                         "finite point (mm) and a reach > 0 mm")
    if args.mesh:
        from data_spec.geometry import read_geometry

        g = read_geometry(args.mesh)
        surface = g.points[g.surface_nodes]
    else:
        surface = read_liver_surface(args.liver)[0]
    gap = float(np.linalg.norm(surface - np.asarray(args.near), axis=1).min())
    if gap > reach:
        raise ValueError(f"--near {args.near}: the liver's surface is {gap:.1f} mm away, "
                         f"beyond the reach of {reach:g} mm (a point in the liver file's frame)")


def _truth_scene(args) -> int:
    from data_spec.atomic import out_problem
    from surrogate.evaluate import truth_scene
    from surrogate.predictor import load_predictor, model_load
    from surrogate.viewer import model_dir

    out = Path(args.out)
    why = next(filter(None, [out_problem(out, "--out"), args.placement
                             and out_problem(args.placement, "--placement")]), None)
    if why:   # before the registration
        return _fail("truth-scene", why)
    if args.sims < 1:
        return _fail("truth-scene", f"--sims {args.sims}: expected a whole number >= 1")
    try:
        mdir = model_dir(Path(args.run))   # its placement only: a model of any load
        pred = load_predictor(mdir, load=model_load(mdir))
        if pred.shape_model is None:
            return _fail("truth-scene", f"{args.run}: its model was not trained on a "
                         "population (no shape model): evaluate it on a dataset of its liver")
        _check_site(args)
        text = truth_scene(pred, args.scene, args.liver, args.sims, args.frame,
                           args.placement, args.mesh, args.near, args.near_radius)
    except (ValueError, OSError) as exc:
        return _fail("truth-scene", str(exc))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"wrote {out}; solve it with: mpirun -n 2 .venv-solver/bin/python -m fem_sim "
          f"generate {out} --out DIR", file=sys.stderr)
    return 0


def _evaluate(args) -> int:
    from data_spec import validate_dataset
    from data_spec.atomic import out_problem
    from surrogate.evaluate import evaluate_own, evaluate_unseen
    from surrogate.predictor import load_predictor
    from surrogate.viewer import model_dir

    why = args.out and out_problem(args.out, "--out")
    if why:   # before the evaluation, not after
        return _fail("evaluate", why)
    problems = validate_dataset(args.data, complete=False)  # held-out subsets are fine
    if problems:
        return _fail("evaluate", f"{args.data}: not a valid dataset: " + "; ".join(problems[:5]))
    try:
        pred = load_predictor(model_dir(Path(args.run)))
        if pred.static is None and not args.liver:
            return _fail("evaluate", f"{args.run}: a model of a population: give --liver, the "
                         "file the dataset was solved on (its truth: truth-scene)")
        if args.liver:   # over the base of the truth's mesh for a model of a base's rest
            result = evaluate_unseen(pred, Path(args.data), args.liver, args.frame,
                                     population_data=args.population, mesh=args.mesh)
        else:
            result = evaluate_own(pred, Path(args.data))
    except (ValueError, OSError) as exc:
        return _fail("evaluate", str(exc))
    text = json.dumps(result, indent=1)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    print(f"MEE {result['network']['mee']:.3f} mm, naive {result['naive']['mee']:.3f} mm, "
          f"skill {result['skill']:.3f} on {result['sims']} simulations")
    return 0


def _adapt(args) -> int:
    from surrogate.data import DataError
    from surrogate.patient import SYNTHETIC, adapt
    from surrogate.viewer import model_dir

    if args.synthetic is None:
        args.synthetic = SYNTHETIC
    if args.sims is not None and args.sims < 0:
        return _fail("adapt", f"--sims: expected an integer >= 0, got {args.sims}")
    if args.synthetic < 1:
        return _fail("adapt", f"--synthetic: expected an integer >= 1, got {args.synthetic}")
    try:
        info = adapt(model_dir(Path(args.model)), args.data, args.liver, args.run,
                     sims=args.sims, frame=args.frame, synthetic=args.synthetic,
                     saved=args.placement, tune=args.tune,
                     rest=model_dir(Path(args.rest)) if args.rest else None,
                     log_fn=lambda m: print(m, file=sys.stderr, flush=True))
    except (DataError, ValueError, OSError) as exc:
        return _fail("adapt", str(exc))
    where = Path(args.run) / ("grasp_patient.npz" if info.get("load") == "grasp" else "model")
    print(f"patient model written to {where} from "
          f"{len(info['fe_simulations'])} FE simulations in {info['seconds']['total']:.0f} s")
    return 0


def _evaluate_patient(args) -> int:
    from data_spec.atomic import out_problem
    from surrogate.data import DataError
    from surrogate.patient.curve import evaluate_patient
    from surrogate.viewer import model_dir

    why = (args.out and out_problem(args.out, "--out")) or out_problem(
        args.results, "--results", directory=True)
    if why:
        return _fail("evaluate-patient", why)
    if args.held < 1:
        return _fail("evaluate-patient", f"--held: expected an integer >= 1, got {args.held}")
    try:
        found = evaluate_patient(model_dir(Path(args.model)), args.data, args.liver,
                                 args.results, ks=args.ks, held=args.held, frame=args.frame,
                                 rest=model_dir(Path(args.rest)) if args.rest else None,
                                 tune=args.tune, log_fn=lambda m: print(m, flush=True))
    except (DataError, ValueError, OSError) as exc:
        return _fail("evaluate-patient", str(exc))
    if not found["ks"]:
        return _fail("evaluate-patient", f"{args.data}: too few simulations for any K with "
                     f"{args.held} held out")
    if args.out:
        Path(args.out).write_text(json.dumps(found, indent=1))
    return 0


def wrong_environment(command: str) -> str | None:
    """Why ``command`` cannot run in this Python (None when it can): the solver environment
    has no JAX.
    """
    import importlib.util

    if importlib.util.find_spec("jax") is not None:
        return None
    return (f"liverfem-surrogate {command}: JAX is not importable by {sys.executable}: this "
            f"command runs in the trainer environment (.venv-train/bin/python -m surrogate "
            f"{command}, or make train); the solver environment runs liverfem-sim")


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    why = wrong_environment(args.command)
    if why:
        print(why, file=sys.stderr)
        return 2
    command = {"train": _train, "predict-liver": _predict_liver, "truth-scene": _truth_scene,
               "evaluate": _evaluate, "adapt": _adapt,
               "evaluate-patient": _evaluate_patient}[args.command]
    return command(args)


if __name__ == "__main__":
    sys.exit(main())
